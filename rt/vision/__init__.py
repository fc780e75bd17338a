"""Measuring poses with a camera: ArUco detection (:mod:`.aruco`), PnP with the pose's
covariance (:mod:`.pnp`) and the rigid transforms they compose (:mod:`.transforms`).

Below both ``calibration`` (the force plate registered to the robot) and ``patients`` (the
malleoli measured for the ankle centre), which may import ``rt`` but not each other.
"""
