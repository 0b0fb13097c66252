"""Studies of section 6: noise (Figs 7-8) and design-space validation (Figs 12-16)."""
