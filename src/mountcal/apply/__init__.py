"""A calibration applied: vectors and tables rotated (:mod:`.rotate`), whole logs streamed into the
vehicle frame (:mod:`.rotate_log`)."""
