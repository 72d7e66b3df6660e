"""The simulator: stops on a slope (:mod:`.stops`), drives (:mod:`.drive`), and the logs it writes
in every format mountcal reads (:mod:`.logs`): the shared truth generator of tests and benchmarks."""
