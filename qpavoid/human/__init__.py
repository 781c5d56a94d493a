"""The person as data: skeleton formats (:mod:`~qpavoid.human.skeleton`, the Kinect v2's in
:mod:`~qpavoid.human.kinect_v2`, every camera's in ``formats/``), each camera's frames as the
body's landmarks (:mod:`~qpavoid.human.landmarks`), one frame of a skeleton or of several
people, the upper-body model of capsules (:mod:`~qpavoid.human.body`: the Kinect v2's and
each camera's on its own joints, ``formats/<format>_body.toml``), postures, and the α-β
filter of a skeleton's joints (:mod:`~qpavoid.human.alpha_beta`, shared by perception and
fusion).

May import: core.
"""
