"""What a calibration produces: the HTML report (:mod:`.report`) and exports to other formats (:mod:`.exporters`)."""
