"""Helpers of the Wald targets (not targets): the paper's views, cameras and lights (views), the
packet measurements and fits (packets), and what a packet's rays need on their own walks (needs)."""
