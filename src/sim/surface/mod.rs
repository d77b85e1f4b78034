//! The LEMAN elastic surface layer model (skin over muscles, fat and connective tissue).
