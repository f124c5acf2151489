"""Helpers of the tool targets (not targets): the calibration, probes and predictions advise and
advise-check share (advising); the named structure variants bench and verify share (variants)."""
