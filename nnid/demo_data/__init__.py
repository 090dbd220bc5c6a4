"""Bundled data of ``nnid demo``: a simulated log and the made-up ``minirov`` vehicle."""
