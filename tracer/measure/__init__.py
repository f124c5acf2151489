"""Measuring: the one timing module, the machine probe, memory budgets and estimates, provenance
(what a measurement depends on)."""
