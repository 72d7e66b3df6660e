"""Estimators: the paper's closed form (:mod:`.paper`) and the maximum-likelihood fit (:mod:`.full`)."""
