// `any_lane` where the device has no subgroup operations: each lane decides for itself. The
// results are the same as shared/any_lane.wgsl's; only lanes wait for one another more often.
fn any_lane(p: bool) -> bool {
    return p;
}
