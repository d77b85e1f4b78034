//! Animation: key postures, splines, timelines, IK and baking (skeleton motions independent of
//! the deformation model).
