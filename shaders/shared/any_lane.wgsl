// Whether `p` holds in any lane of the invocation's subgroup: a loop that breaks on it breaks in
// all lanes together. A CPU driver runs every branch for all its lanes, so work after such a loop
// runs once for the subgroup, when one of its lanes needs it. The kernel built without subgroup
// operations takes shared/each_lane.wgsl instead.
fn any_lane(p: bool) -> bool {
    return subgroupAny(p);
}
