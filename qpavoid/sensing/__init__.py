"""What the cell's cameras give: calibration and keys, recordings (merged and per sensor),
the signed wire format, the UDP receiver and streamer, a synthetic sensor pair.

May import: core, human.
"""
