"""Logs: the VehicleLog contract and its validation, excitation signals and the simulator."""
