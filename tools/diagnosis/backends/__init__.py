"""The models a diagnosis rolls out: the LCS effect library of the cart-pole and ball
rolling (effects), the rigid-object LCS (rigid_model) and Drake's MultibodyPlant
(drake_backend, with the force elements Drake lacks in drake_forces), behind the protocol
of model_backend.

Imports only the backends."""
