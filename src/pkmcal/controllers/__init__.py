"""Real controllers (LinuxCNC, Klipper) run on pkmcal's exports."""
