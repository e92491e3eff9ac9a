"""The proof harnesses: recordings with a concealed effect made by another simulator
(cart-pole, ball rolling, rigid objects), the hit-rate runs that score `diagnose` on them,
the clean-data floor and the SINDy-style baseline. Imports anything in
tools/diagnosis; only the harness, tools/bench and tests import it."""
