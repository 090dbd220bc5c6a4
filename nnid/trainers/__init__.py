"""Estimators: least squares with uncertainty, recursive estimators, Caccia's procedure, ..."""
