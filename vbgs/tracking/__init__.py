"""Camera tracking against a map: the pose of an arriving frame from the map's
posterior (:mod:`vbgs.tracking.register`), rigid motions (:mod:`vbgs.tracking.se3`),
trajectory metrics (:mod:`vbgs.tracking.trajectory`) and a drifting odometry
(:mod:`vbgs.tracking.drift`)."""
