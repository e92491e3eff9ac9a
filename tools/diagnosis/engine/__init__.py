"""The diagnosis engine, the same for every task and model: replay and locate the mismatch
(locate), fit candidate effects with intervals and pick what held-out data supports (fit),
judge the evidence and propose a separating excitation (evidence), write the report (report).

Imports only the engine and the backends."""
