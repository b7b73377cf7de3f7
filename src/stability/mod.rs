//! Torsional stability: the 1-DOF lumped model, stability maps over (Ω, W); the
//! finite-element string arrives next.

pub mod lumped;
pub mod map;
