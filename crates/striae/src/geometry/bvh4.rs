//! A 4-wide BVH with SIMD box tests, collapsed from obvhs' binary BVH (PLOC + reinsertion),
//! in the style of Embree's BVH4 (Wald et al. 2014, "Embree: A Kernel Framework for Efficient
//! CPU Ray Tracing"): every node stores its four children's boxes as structure-of-arrays, so one
//! node visit tests four boxes with `Vec4` (SSE) arithmetic.
//!
//! * **Collapse**: starting from a binary node's two children, the interior child of largest
//!   surface area is replaced by its two children until there are four (the usual BVH2 to BVHN
//!   conversion, e.g. Wald et al. 2008, "Getting Rid of Packets").
//! * **Box test**: the slab test with the near/far slab chosen by the sign of each direction
//!   component, `t_far` scaled by `1 + 2 gamma(3)` so rounding never misses a box the ray
//!   touches (pbrt-v4 `Bounds3::IntersectP`, Ize 2013 "Robust BVH Ray Traversal"). Zero
//!   direction components are replaced by `+-1e-30`, so no `0 * inf` NaN appears. The entry
//!   distance is clamped at `0`, with no minimum offset: geometry arbitrarily close to the origin
//!   is found (the CWBVH of obvhs 0.4 needs a 2e-4 workaround for this).
//! * **Traversal**: closest-hit front to back (children sorted by entry distance, a stack of
//!   `(node, entry distance)` pairs culled against the current closest `t`); any-hit with an
//!   early exit. Leaves are contiguous ranges of primitives, tested by the caller's closure.

use std::mem::MaybeUninit;

use glam::Vec4;
use obvhs::bvh2::Bvh2;

use crate::math::Vec3;

/// Leaf children have this bit set; the rest is `first << COUNT_BITS | count`.
const LEAF: u32 = 1 << 31;
const COUNT_BITS: u32 = 4;
const MAX_LEAF_PRIMS: u32 = (1 << COUNT_BITS) - 1;
/// Traversal stack size; a tree that could overflow it is not built (see [`Bvh4::from_bvh2`]).
const STACK: usize = 192;

/// Four children: their boxes as `[min_x, min_y, min_z, max_x, max_y, max_z]` lanes, and what
/// they are (interior node index, or [`LEAF`] with a primitive range).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct Node4 {
    bounds: [Vec4; 6],
    child: [u32; 4],
}

/// The 4-wide BVH; primitive ranges index the caller's primitive array in BVH order (the order
/// of the source [`Bvh2`]'s `primitive_indices`).
#[derive(Clone, Debug)]
pub(crate) struct Bvh4 {
    nodes: Vec<Node4>,
}

/// Per-ray constants of the box test.
struct BoxRay {
    o: [Vec4; 3],
    inv_d: [Vec4; 3],
    /// Index into `Node4::bounds` of the near and far slab per axis.
    near: [usize; 3],
    far: [usize; 3],
}

impl BoxRay {
    #[inline(always)]
    fn new(o: Vec3, d: Vec3) -> BoxRay {
        let mut inv = [0.0f32; 3];
        let mut near = [0usize; 3];
        let mut far = [0usize; 3];
        for a in 0..3 {
            let da = if d[a].abs() < 1e-30 {
                if d[a].is_sign_negative() {
                    -1e-30
                } else {
                    1e-30
                }
            } else {
                d[a]
            };
            inv[a] = 1.0 / da;
            if inv[a] < 0.0 {
                near[a] = a + 3;
                far[a] = a;
            } else {
                near[a] = a;
                far[a] = a + 3;
            }
        }
        BoxRay {
            o: [Vec4::splat(o.x), Vec4::splat(o.y), Vec4::splat(o.z)],
            inv_d: [
                Vec4::splat(inv[0]),
                Vec4::splat(inv[1]),
                Vec4::splat(inv[2]),
            ],
            near,
            far,
        }
    }

    /// `(entry distances, hit mask)` of the four children for `t` in `[0, t_max]`.
    #[inline(always)]
    fn test(&self, node: &Node4, t_max: f32) -> (Vec4, u32) {
        let b = &node.bounds;
        let tn0 = (b[self.near[0]] - self.o[0]) * self.inv_d[0];
        let tn1 = (b[self.near[1]] - self.o[1]) * self.inv_d[1];
        let tn2 = (b[self.near[2]] - self.o[2]) * self.inv_d[2];
        let tf0 = (b[self.far[0]] - self.o[0]) * self.inv_d[0];
        let tf1 = (b[self.far[1]] - self.o[1]) * self.inv_d[1];
        let tf2 = (b[self.far[2]] - self.o[2]) * self.inv_d[2];
        let t_near = tn0.max(tn1).max(tn2.max(Vec4::ZERO));
        // 1 + 2 gamma(3) (pbrt-v4): rounding never shrinks the interval below the true one.
        let t_far = tf0.min(tf1).min(tf2)
            * (1.0 + 2.0 * 3.0 * f32::EPSILON * 0.5 / (1.0 - 1.5 * f32::EPSILON));
        let t_far = t_far.min(Vec4::splat(t_max));
        (t_near, t_near.cmple(t_far).bitmask())
    }
}

impl Bvh4 {
    /// Collapses `bvh` (whose leaves hold at most 15 primitives). `None` when the tree is too
    /// deep for the fixed traversal stack (the caller then keeps another hierarchy).
    pub(crate) fn from_bvh2(bvh: &Bvh2) -> Option<Bvh4> {
        if bvh.nodes.is_empty() {
            return None;
        }
        let mut out = Bvh4 { nodes: Vec::new() };
        let depth = out.build(bvh, &[0])?;
        // The stack holds at most 3 entries per level (the nearest child is visited directly).
        (3 * depth + 4 <= STACK).then_some(out)
    }

    /// Appends the node whose children are the binary nodes `start` (opened up to four);
    /// returns the depth of the subtree.
    fn build(&mut self, bvh: &Bvh2, start: &[usize]) -> Option<usize> {
        let mut kids: Vec<usize> = start.to_vec();
        if kids.len() == 1 && bvh.nodes[kids[0]].prim_count == 0 {
            let n = &bvh.nodes[kids[0]];
            kids = vec![n.first_index as usize, n.first_index as usize + 1];
        }
        while kids.len() < 4 {
            // Open the interior child of largest area.
            let best = kids
                .iter()
                .enumerate()
                .filter(|(_, &k)| bvh.nodes[k].prim_count == 0)
                .max_by(|a, b| {
                    let (ha, hb) = (
                        bvh.nodes[*a.1].aabb.half_area(),
                        bvh.nodes[*b.1].aabb.half_area(),
                    );
                    ha.total_cmp(&hb)
                })
                .map(|(i, _)| i);
            let Some(i) = best else { break };
            let n = &bvh.nodes[kids[i]];
            let first = n.first_index as usize;
            kids[i] = first;
            kids.push(first + 1);
        }
        let index = self.nodes.len();
        let mut node = Node4 {
            bounds: [
                Vec4::splat(f32::INFINITY),
                Vec4::splat(f32::INFINITY),
                Vec4::splat(f32::INFINITY),
                Vec4::splat(f32::NEG_INFINITY),
                Vec4::splat(f32::NEG_INFINITY),
                Vec4::splat(f32::NEG_INFINITY),
            ],
            child: [LEAF; 4],
        };
        self.nodes.push(node);
        let mut depth = 1;
        for (lane, &k) in kids.iter().enumerate() {
            let n = &bvh.nodes[k];
            for a in 0..3 {
                node.bounds[a][lane] = n.aabb.min[a];
                node.bounds[a + 3][lane] = n.aabb.max[a];
            }
            if n.prim_count > 0 {
                if n.prim_count > MAX_LEAF_PRIMS || n.first_index >= 1 << (31 - COUNT_BITS) {
                    return None;
                }
                node.child[lane] = LEAF | n.first_index << COUNT_BITS | n.prim_count;
            } else {
                node.child[lane] = self.nodes.len() as u32;
                depth = depth.max(1 + self.build(bvh, &[k])?);
            }
        }
        self.nodes[index] = node;
        Some(depth)
    }

    /// Closest-hit traversal: `leaf(first, count, &mut t_max)` tests primitives
    /// `first..first + count` and lowers `t_max` to any hit it finds.
    #[inline(always)]
    pub(crate) fn closest(
        &self,
        o: Vec3,
        d: Vec3,
        mut t_max: f32,
        mut leaf: impl FnMut(usize, usize, &mut f32),
    ) {
        let ray = BoxRay::new(o, d);
        let mut stack = [MaybeUninit::<(u32, f32)>::uninit(); STACK];
        let mut sp = 0usize;
        let mut cur = 0u32;
        loop {
            if cur & LEAF == 0 {
                let node = &self.nodes[cur as usize];
                let (t_near, mut mask) = ray.test(node, t_max);
                if mask != 0 {
                    // Usually one child is hit (visit it), sometimes two (push the farther):
                    // only three or four hits take the general sort.
                    let lane0 = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    if mask == 0 {
                        cur = node.child[lane0];
                        continue;
                    }
                    let t = t_near.to_array();
                    let lane1 = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    let (h0, h1) = ((node.child[lane0], t[lane0]), (node.child[lane1], t[lane1]));
                    let (near, far) = if h1.1 < h0.1 { (h1, h0) } else { (h0, h1) };
                    if mask == 0 {
                        stack[sp].write(far);
                        sp += 1;
                        cur = near.0;
                        continue;
                    }
                    // Three or four: insertion sort, nearest first.
                    let mut hits = [near, far, (0, 0.0), (0, 0.0)];
                    let mut n = 2;
                    while mask != 0 {
                        let lane = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        let entry = (node.child[lane], t[lane]);
                        let mut j = n;
                        while j > 0 && hits[j - 1].1 > entry.1 {
                            hits[j] = hits[j - 1];
                            j -= 1;
                        }
                        hits[j] = entry;
                        n += 1;
                    }
                    for &h in hits[1..n].iter().rev() {
                        stack[sp].write(h);
                        sp += 1;
                    }
                    cur = hits[0].0;
                    continue;
                }
            } else {
                let first = ((cur & !LEAF) >> COUNT_BITS) as usize;
                let count = (cur & MAX_LEAF_PRIMS) as usize;
                leaf(first, count, &mut t_max);
            }
            // Pop the next entry still in front of the closest hit.
            loop {
                if sp == 0 {
                    return;
                }
                sp -= 1;
                // SAFETY: entries below `sp` were written (pushes write before incrementing).
                let (c, t) = unsafe { stack[sp].assume_init() };
                if t <= t_max {
                    cur = c;
                    break;
                }
            }
        }
    }

    /// Any-hit traversal: `leaf(first, count)` returns whether a primitive of the range is hit;
    /// the first `true` ends the traversal.
    #[inline(always)]
    pub(crate) fn any(
        &self,
        o: Vec3,
        d: Vec3,
        t_max: f32,
        mut leaf: impl FnMut(usize, usize) -> bool,
    ) -> bool {
        let ray = BoxRay::new(o, d);
        let mut stack = [MaybeUninit::<u32>::uninit(); STACK];
        let mut sp = 0usize;
        let mut cur = 0u32;
        loop {
            if cur & LEAF == 0 {
                let node = &self.nodes[cur as usize];
                let (_, mut mask) = ray.test(node, t_max);
                if mask != 0 {
                    let lane = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    cur = node.child[lane];
                    while mask != 0 {
                        let l = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        stack[sp].write(node.child[l]);
                        sp += 1;
                    }
                    continue;
                }
            } else {
                let first = ((cur & !LEAF) >> COUNT_BITS) as usize;
                let count = (cur & MAX_LEAF_PRIMS) as usize;
                if leaf(first, count) {
                    return true;
                }
            }
            if sp == 0 {
                return false;
            }
            sp -= 1;
            // SAFETY: entries below `sp` were written (pushes write before incrementing).
            cur = unsafe { stack[sp].assume_init() };
        }
    }
}
