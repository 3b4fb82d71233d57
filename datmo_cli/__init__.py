"""datmo: detection and tracking of moving objects in 2D laser-scanner logs."""

__version__ = "0.1.0"
