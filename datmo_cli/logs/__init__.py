"""Reading and writing datmo logs (MCAP), message codecs and importers."""
