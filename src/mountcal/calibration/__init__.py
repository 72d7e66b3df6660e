"""A calibration: the fit of a stop table, combined with driving; a log → a calibration."""
