"""The QP's limits: the joints' position and velocity bounds and the velocity damper."""
