//! The character model as data: skeleton, muscles and bones, fat, connective tissue, skin; its
//! file format.
