//! Torsional stability: the 1-DOF lumped model now; the finite-element string and the maps
//! arrive with the stability issue.

pub mod lumped;
