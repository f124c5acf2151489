"""Helpers of the Ize targets (not targets): the memory-aware model's constants (memmodel) and the
memory-free cost probe (memprobe)."""
