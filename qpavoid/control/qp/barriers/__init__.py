"""The QP's barriers against the person: the paper's repulsion and speed and separation."""
