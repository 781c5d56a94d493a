"""What the cell's cameras give: calibration and keys, recordings (merged and per sensor),
the signed wire format, the UDP receiver and streamer, a synthetic sensor pair, a camera's
latency measured against the arm's encoders.

May import: core, arm (the arm's forward kinematics, for the latency), human.
"""
