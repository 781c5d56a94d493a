"""The QP's tasks: costs it minimises (end-effector path, elbow, posture, regularisation)."""
