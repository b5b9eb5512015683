"""Trial analysis: Vicon CSV import, CoM height and step periods, comparison with the simulator."""
