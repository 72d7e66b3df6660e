"""Sample tables (CSV, Parquet): read whole or in batches (:mod:`.read`), written (:mod:`.write`)."""
