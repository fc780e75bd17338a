"""The safety supervisor: limits in three layers, checks every cycle, latched reactions."""
