"""Logs in: the only package that imports format libraries (can, cantools, mcap, asammdf)."""
