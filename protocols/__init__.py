"""talus: protocols (see DESIGN.md section 2)."""
