"""Model files (URDF/SDF) and the Python that builds them into plants: the cart-pole,
the Panda, the ball-rolling scene and the controller's model, the fruit.

May import the generic core of systems/ (contact/) only."""
