//! Torsional stability: the paper's 1-DOF model (closed-form 2x2 criterion), the
//! finite-element drill string of its appendix, and maps over (Ω, W) that reduce both to a
//! critical bit damping.

pub mod fe;
pub mod lumped;
pub mod map;
