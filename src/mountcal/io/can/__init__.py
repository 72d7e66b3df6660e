"""CAN logs: frames from every python-can / asammdf format (:mod:`.frames`), signals through a DBC
(:mod:`.dbc`, :mod:`.signals`), the IMU reader (:mod:`.read`), the writer (:mod:`.write`) and live buses
(:mod:`.bus`)."""
