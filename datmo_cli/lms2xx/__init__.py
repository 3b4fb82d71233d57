"""LMS2xx serial protocol, driver and emulator."""
