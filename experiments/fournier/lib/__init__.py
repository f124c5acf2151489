"""Helpers of fournier-table1 (not targets): the SPD-style and teapot scenes (scenes) and the Around
Again scene's measurements (around)."""
