"""Sizes shared by every page (GUI.md: a clinic touchscreen at 1366×768)."""
from __future__ import annotations

#: Smallest touch target, px.
TARGET_PX = 40
#: Height of the large buttons of a page (cards, rail, Start), px.
LARGE_PX = 56
