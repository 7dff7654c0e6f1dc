"""Rehearsals: fly a scenario against the bundled simulator (or vehicles already
running), judge it on the simulator's truth, write the flight record and its report."""
