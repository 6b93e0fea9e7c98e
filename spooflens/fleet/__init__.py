"""Seed 004: several vehicles (or receivers) under one attacker. Position offsets against each vehicle's
own independent reference, their homology index (Algorithm 1), attack simulation on pseudoranges, the
distributed secure state observer, and the `spooflens fleet` command."""
