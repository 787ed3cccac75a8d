"""The onboard PC's joint layer: cylinder <-> joint conversion of the two-DoF universal joints
driven by two linear EHAs (thesis 6.2.1, Eq. 6.1-6.6) and the 1 kHz joint position/torque
loops over the MCU force loops (thesis 5.5, Fig. 5.12)."""
