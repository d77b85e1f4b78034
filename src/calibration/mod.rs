//! Screen calibration: the screen rectangle from measured corners, tracker frames, profiles.
