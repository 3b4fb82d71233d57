"""One module per CLI command; each defines a single Click command."""
