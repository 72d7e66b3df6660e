"""Stops: detection in a log, their headings, near misses, and the stop table."""
