"""Fault detection from residuals: a streaming monitor on a trained physics model
(:mod:`nnid.fault.monitor`, compiled hot path in :mod:`nnid.fault.kernel`), thresholds for a
target false-alarm rate (:mod:`nnid.fault.thresholds`), isolation and estimation of each alarm
with the residual loop's candidates (:mod:`nnid.fault.isolation`), whole logs
(:mod:`nnid.fault.detect`) and live ones (:mod:`nnid.fault.follow`)."""
