"""Colours shared by every figure of the project (one per spasticity level)."""

#: One colour per spasticity level, from mild to severe (the paper's Fig. 5
#: caption: green, yellow, orange, red).
LEVEL_COLORS: dict[int, str] = {0: "#2ca02c", 1: "#e6b800", 2: "#ff7f0e", 3: "#d62728"}
