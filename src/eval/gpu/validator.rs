//! The naga validator a kernel is held to, at build time (build.rs includes this file) and by
//! the tests: the same rules in both places.

use naga::valid::{Capabilities, ShaderStages, SubgroupOperationSet, ValidationFlags, Validator};

/// The validator for kernel `name` (as `KERNELS` in build.rs names it). Only the coupled kernel
/// votes in its subgroup; its twin without subgroup operations, and every other kernel, must
/// run on a device that has none.
pub fn validator(name: &str) -> Validator {
    let capabilities = match name {
        "coupled" => Capabilities::SUBGROUP,
        _ => Capabilities::empty(),
    };
    let mut validator = Validator::new(ValidationFlags::all(), capabilities);
    validator
        .subgroup_stages(ShaderStages::COMPUTE)
        .subgroup_operations(SubgroupOperationSet::VOTE);
    validator
}
