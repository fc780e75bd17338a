"""Position controllers behind one interface (thesis 3.6): PID, PD+G, PD+G0, Paden-Panja,
computed torque (point-to-point and trajectory) and adaptive (Slotine-Li)."""
