//! Tracking: pose filtering (One Euro) and prediction, tracker-to-world frames.
