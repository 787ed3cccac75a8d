"""Hydra's hip pitch/roll joint as a load: the thigh on the universal joint, driven by two
EHA plants through their connecting rods (thesis 6.2.1-6.2.2, 5.4)."""
