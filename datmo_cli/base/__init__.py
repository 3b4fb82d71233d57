"""The base layer, usable by every other and importing only itself: errors, safe inputs and outputs, bounds,
progress, text, trigonometry with the same bits everywhere, and numba's set-up."""
