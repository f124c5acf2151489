"""Helpers of the Hapala targets (not targets): the calibration measurements every Hapala target and
advise read (calibrate), and the stand-ins and summary claims (claims)."""
