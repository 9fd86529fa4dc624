//! A wide BVH with SIMD box tests, collapsed from obvhs' binary BVH (PLOC + reinsertion), in
//! the style of Embree's BVH8/BVH8 (Wald et al. 2014, "Embree: A Kernel Framework for Efficient
//! CPU Ray Tracing"): every node stores its children's boxes as structure-of-arrays, one row
//! of [`WIDTH`] = 8 lanes per slab, so one node visit tests all children at once (8 children instead
//! of 4: glass teapot 2.11 -> 1.96 s, 16 spp, one thread; `BENCHMARKS.md`, "Design findings").
//! The lane loops of the box test compile to pairs of 128-bit
//! instructions in every copy of the render loop, to match the two `movmskps` halves of the hit
//! mask ([`lanes_le`]): a lane loop for the mask built it bit by bit. 256-bit intrinsics measured
//! 3-4 % faster per secondary ray alone, but inlined into the AVX copies (chosen by a flag a ray)
//! they take 0.7 % fewer instructions a sample and no time in a render (`BENCHMARKS.md`,
//! "Measured and rejected").
//!
//! * **Collapse**: starting from a binary node's two children, the interior child of largest
//!   surface area is replaced by its two children until there are [`WIDTH`] (the usual BVH2 to
//!   BVHN conversion, e.g. Wald et al. 2008, "Getting Rid of Packets").
//! * **Box test**: the slab test with the near/far slab chosen by the sign of each direction
//!   component, `t_far` scaled by `1 + 2 gamma(3)` so rounding never misses a box the ray
//!   touches (pbrt-v4 `Bounds3::IntersectP`, Ize 2013 "Robust BVH Ray Traversal"). Zero
//!   direction components are replaced by `+-1e-30`, so no `0 * inf` NaN appears. The entry
//!   distance is clamped at `0`, with no minimum offset: geometry arbitrarily close to the origin
//!   is found (the CWBVH of obvhs 0.4 needs a 2e-4 workaround for this).
//! * **Traversal**: closest-hit front to back (children sorted by entry distance, a stack of
//!   `(node, entry distance)` pairs culled against the current closest `t`); any-hit with an
//!   early exit.
//! * **Packets** ([`Bvh8::closest_packet`]): the camera rays of one pixel share their origin
//!   and nearly their direction, so they are traversed together, once, with the interval of
//!   their inverse directions (Wald et al. 2007, "Ray Tracing Deformable Scenes Using Dynamic
//!   Bounding Volume Hierarchies": the interval-arithmetic test of a packet against a box);
//!   each ray then tests the leaves on its own. Rounding is monotone, so the interval test
//!   accepts every box any of the rays' own tests accepts, bit for bit, and every ray finds its
//!   closest hit: the one its own traversal finds, but for exact ties in `t`, which the
//!   visiting order breaks.
//! * **Leaves**: every binary subtree of at most four primitives becomes one leaf block, whose
//!   four triangles the caller stores as structure of arrays (`bvh::Tri4`) and tests at once
//!   with SSE (Embree's `Triangle4` leaves, Wald et al. 2014); a leaf with a sphere is tested
//!   primitive by primitive.

use std::mem::MaybeUninit;

use glam::Vec4;

use obvhs::bvh2::Bvh2;

use crate::math::Vec3;

/// Leaf children have this bit set; the rest is `block << COUNT_BITS | count`, plus
/// [`SCALAR`] for a block that holds a sphere.
const LEAF: u32 = 1 << 31;
/// A leaf block holding a non-triangle primitive (tested one primitive at a time).
const SCALAR: u32 = 1 << 30;
const COUNT_BITS: u32 = 3;
const COUNT_MASK: u32 = (1 << COUNT_BITS) - 1;
/// Primitives per leaf block: a leaf is one block of up to four primitives, tested at once with
/// SSE (`bvh::Tri4`); a binary subtree of at most this many primitives becomes one leaf.
pub(crate) const BLOCK: usize = 4;
/// Traversal stack size; a tree that could overflow it is not built (see [`Bvh8::from_bvh2`]).
const STACK: usize = 192;
/// Children per node: one 256-bit AVX2 register (two SSE registers in the portable copy) per
/// slab.
const WIDTH: usize = 8;

/// A leaf as the traversal hands it to the caller's test: block `block` holds primitives
/// `BLOCK * block .. BLOCK * block + count` of the primitive order [`Bvh8::from_bvh2`] returns
/// (padded lanes repeat the last primitive); `scalar` when one of them is not a triangle.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Leaf {
    pub block: usize,
    pub count: usize,
    pub scalar: bool,
}

/// The caller's primitive test for the closest hit (a trait rather than a closure so that it
/// can be forced inline into the traversal loop).
pub(crate) trait ClosestLeaf {
    /// Test the leaf's primitives for the closest hit, lowering `t_max` to any hit found.
    fn closest(&mut self, leaf: Leaf, t_max: &mut f32);
}

/// The caller's primitive test for any hit.
pub(crate) trait AnyLeaf {
    /// Whether any primitive of the leaf is hit before `t_max`.
    fn any(&mut self, leaf: Leaf, t_max: f32) -> bool;
}

impl Leaf {
    #[inline(always)]
    fn decode(child: u32) -> Leaf {
        Leaf {
            block: ((child & !(LEAF | SCALAR)) >> COUNT_BITS) as usize,
            count: (child & COUNT_MASK) as usize,
            scalar: child & SCALAR != 0,
        }
    }
}

/// [`WIDTH`] children: their boxes as `[min_x, min_y, min_z, max_x, max_y, max_z]` rows of
/// one lane per child, and what they are (interior node index, or [`LEAF`] with a primitive
/// range).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct Node8 {
    bounds: [[f32; WIDTH]; 6],
    child: [u32; WIDTH],
}

/// The 4-wide BVH; primitive ranges index the caller's primitive array in BVH order (the order
/// of the source [`Bvh2`]'s `primitive_indices`).
#[derive(Clone, Debug)]
pub(crate) struct Bvh8 {
    nodes: Vec<Node8>,
}

/// A box test of the closest-hit traversal: `(entry distances, hit mask)` of a node's children
/// for `t` in `[0, t_max]`.
trait NodeTest {
    fn test(&self, node: &Node8, t_max: f32) -> ([f32; WIDTH], u32);
}

/// `1 / d` with zero components replaced by `+-1e-30` (no `0 * inf` NaN in the slab test), and
/// the index of the near and far slab of the axis.
#[inline(always)]
fn slab_inverse(d: f32, a: usize) -> (f32, usize, usize) {
    let da = if d.abs() < 1e-30 {
        if d.is_sign_negative() {
            -1e-30
        } else {
            1e-30
        }
    } else {
        d
    };
    let inv = 1.0 / da;
    if inv < 0.0 {
        (inv, a + 3, a)
    } else {
        (inv, a, a + 3)
    }
}

/// Per-ray constants of the box test.
struct BoxRay {
    o: [f32; 3],
    inv_d: [f32; 3],
    /// Index into `Node8::bounds` of the near and far slab per axis.
    near: [usize; 3],
    far: [usize; 3],
}

/// `maxps` / `minps` semantics (`a` when the comparison holds, else `b`), written so that the
/// lane loops below vectorise to single `vmaxps` / `vminps` instructions.
#[inline(always)]
fn max_ps(a: f32, b: f32) -> f32 {
    if a > b {
        a
    } else {
        b
    }
}

#[inline(always)]
fn min_ps(a: f32, b: f32) -> f32 {
    if a < b {
        a
    } else {
        b
    }
}

/// `1 + 2 gamma(3)` (pbrt-v4): scaling `t_far` by it keeps rounding from shrinking the
/// interval below the true one.
const T_FAR_SCALE: f32 = 1.0 + 2.0 * 3.0 * f32::EPSILON * 0.5 / (1.0 - 1.5 * f32::EPSILON);

impl BoxRay {
    #[inline(always)]
    fn new(o: Vec3, d: Vec3) -> BoxRay {
        let mut inv = [0.0f32; 3];
        let mut near = [0usize; 3];
        let mut far = [0usize; 3];
        for a in 0..3 {
            (inv[a], near[a], far[a]) = slab_inverse(d[a], a);
        }
        BoxRay {
            o: o.to_array(),
            inv_d: inv,
            near,
            far,
        }
    }
}

/// `cmpleps` + `movmskps` per half of the lanes (a lane loop would build the mask bit by bit).
#[inline(always)]
fn lanes_le(a: &[f32; WIDTH], b: &[f32; WIDTH]) -> u32 {
    let half = |k: usize| {
        Vec4::from_slice(&a[k..k + 4])
            .cmple(Vec4::from_slice(&b[k..k + 4]))
            .bitmask()
    };
    half(0) | half(4) << 4
}

impl NodeTest for BoxRay {
    #[inline(always)]
    fn test(&self, node: &Node8, t_max: f32) -> ([f32; WIDTH], u32) {
        let inv = self.inv_d;
        let t = |a: usize, d: f32| d * inv[a];
        slab_test(node, self.o, self.near, self.far, t_max, t, t)
    }
}

/// The slab test of [`BoxRay`] and [`PacketBoxRay`]: per child, the distances
/// `near_t(axis, b - o)` to its near slabs and `far_t(axis, b - o)` to its far slabs, entered at
/// the largest near one (at least 0) and left at the smallest far one (scaled by
/// [`T_FAR_SCALE`], at most `t_max`); `(entry distances, hit mask)`. Written as loops over the
/// [`WIDTH`] lanes, which every copy of the render loop runs as pairs of 128-bit instructions
/// (see the module doc); all copies compute the same IEEE operations.
#[inline(always)]
fn slab_test(
    node: &Node8,
    [o0, o1, o2]: [f32; 3],
    near: [usize; 3],
    far: [usize; 3],
    t_max: f32,
    near_t: impl Fn(usize, f32) -> f32,
    far_t: impl Fn(usize, f32) -> f32,
) -> ([f32; WIDTH], u32) {
    let b = &node.bounds;
    let (bn0, bn1, bn2) = (&b[near[0]], &b[near[1]], &b[near[2]]);
    let (bf0, bf1, bf2) = (&b[far[0]], &b[far[1]], &b[far[2]]);
    let mut t_near = [0.0f32; WIDTH];
    let mut t_far = [0.0f32; WIDTH];
    for k in 0..WIDTH {
        let tn0 = near_t(0, bn0[k] - o0);
        let tn1 = near_t(1, bn1[k] - o1);
        let tn2 = near_t(2, bn2[k] - o2);
        let tf0 = far_t(0, bf0[k] - o0);
        let tf1 = far_t(1, bf1[k] - o1);
        let tf2 = far_t(2, bf2[k] - o2);
        let tn = max_ps(max_ps(tn0, tn1), max_ps(tn2, 0.0));
        let tf = min_ps(min_ps(min_ps(tf0, tf1), tf2) * T_FAR_SCALE, t_max);
        t_near[k] = tn;
        t_far[k] = tf;
    }
    (t_near, lanes_le(&t_near, &t_far))
}

/// Most rays of a packet ([`Bvh8::closest_packet`]).
pub const PACKET: usize = 32;

/// The box test of a packet of rays with one origin and the same sign of each direction
/// component: the slab distances with each axis's inverse direction in `[inv_lo, inv_hi]`.
struct PacketBoxRay {
    o: [f32; 3],
    inv_lo: [f32; 3],
    inv_hi: [f32; 3],
    near: [usize; 3],
    far: [usize; 3],
}

impl PacketBoxRay {
    /// `None` when the directions' signs differ on some axis (the near slab differs).
    #[inline(always)]
    fn new(o: Vec3, dirs: &[Vec3]) -> Option<PacketBoxRay> {
        let first = BoxRay::new(o, dirs[0]);
        let (mut lo, mut hi) = (first.inv_d, first.inv_d);
        for &d in &dirs[1..] {
            for a in 0..3 {
                let (inv, near, _) = slab_inverse(d[a], a);
                if near != first.near[a] {
                    return None;
                }
                lo[a] = lo[a].min(inv);
                hi[a] = hi[a].max(inv);
            }
        }
        Some(PacketBoxRay {
            o: first.o,
            inv_lo: lo,
            inv_hi: hi,
            near: first.near,
            far: first.far,
        })
    }
}

impl NodeTest for PacketBoxRay {
    /// [`BoxRay`]'s test with each product `(b - o) inv` replaced by its least (near slabs) or
    /// greatest (far slabs) value over `inv` in `[inv_lo, inv_hi]`: a product rounds
    /// monotonically in `inv`, so every ray's own `t_near` is at least, and its `t_far` at
    /// most, what this gives, and every child any ray's test accepts is accepted.
    #[inline(always)]
    fn test(&self, node: &Node8, t_max: f32) -> ([f32; WIDTH], u32) {
        let (lo, hi) = (self.inv_lo, self.inv_hi);
        let near_t = |a: usize, d: f32| min_ps(d * lo[a], d * hi[a]);
        let far_t = |a: usize, d: f32| max_ps(d * lo[a], d * hi[a]);
        slab_test(node, self.o, self.near, self.far, t_max, near_t, far_t)
    }
}

/// State of [`Bvh8::from_bvh2`].
struct Builder<'a, F: Fn(u32) -> bool> {
    bvh: &'a Bvh2,
    /// Primitive count of each binary subtree.
    under: Vec<u32>,
    is_scalar: &'a F,
    out: Bvh8,
    order: Vec<u32>,
}

impl<F: Fn(u32) -> bool> Builder<'_, F> {
    /// Whether binary node `k` becomes a leaf block.
    fn is_leaf(&self, k: usize) -> bool {
        self.bvh.nodes[k].prim_count > 0 || self.under[k] as usize <= BLOCK
    }

    /// Appends the primitives under binary node `k` to `out`.
    fn gather(&self, k: usize, out: &mut Vec<u32>) {
        let n = &self.bvh.nodes[k];
        if n.prim_count > 0 {
            let first = n.first_index as usize;
            out.extend_from_slice(
                &self.bvh.primitive_indices[first..first + n.prim_count as usize],
            );
        } else {
            self.gather(n.first_index as usize, out);
            self.gather(n.first_index as usize + 1, out);
        }
    }

    /// The child words of the leaf blocks holding the primitives under binary node `k` (more
    /// than one only when a binary leaf holds more than [`BLOCK`] primitives).
    fn leaf_blocks(&mut self, k: usize) -> Vec<u32> {
        let mut prims = Vec::new();
        self.gather(k, &mut prims);
        prims
            .chunks(BLOCK)
            .map(|chunk| {
                let block = (self.order.len() / BLOCK) as u32;
                let scalar = chunk.iter().any(|&i| (self.is_scalar)(i));
                for lane in 0..BLOCK {
                    self.order.push(chunk[lane.min(chunk.len() - 1)]);
                }
                LEAF | if scalar { SCALAR } else { 0 } | block << COUNT_BITS | chunk.len() as u32
            })
            .collect()
    }

    /// Appends the 4-wide node for binary node `root` (opened up to four children) and its
    /// subtree; returns the subtree's depth.
    fn build(&mut self, root: usize) -> Option<usize> {
        let bvh = self.bvh;
        let mut kids: Vec<usize> = vec![root];
        while kids.len() < WIDTH {
            // Open the interior child of largest area.
            let best = kids
                .iter()
                .enumerate()
                .filter(|(_, &k)| !self.is_leaf(k))
                .max_by(|a, b| {
                    let (ha, hb) = (
                        bvh.nodes[*a.1].aabb.half_area(),
                        bvh.nodes[*b.1].aabb.half_area(),
                    );
                    ha.total_cmp(&hb)
                })
                .map(|(i, _)| i);
            let Some(i) = best else { break };
            let first = bvh.nodes[kids[i]].first_index as usize;
            kids[i] = first;
            kids.push(first + 1);
        }
        // Children as (binary node, child word, or `None` for an interior node to expand).
        let mut lanes: Vec<(usize, Option<u32>)> = Vec::new();
        for &k in &kids {
            if self.is_leaf(k) {
                for word in self.leaf_blocks(k) {
                    lanes.push((k, Some(word)));
                }
            } else {
                lanes.push((k, None));
            }
        }
        if lanes.len() > WIDTH {
            // A binary leaf of more than BLOCK primitives spilled over (`Geometry` builds the
            // binary BVH with leaves of at most BLOCK primitives, so this does not happen).
            return None;
        }
        if self.order.len() / BLOCK >= 1 << (30 - COUNT_BITS) {
            return None;
        }
        let index = self.out.nodes.len();
        let (inf, neg) = (f32::INFINITY, f32::NEG_INFINITY);
        let mut node = Node8 {
            bounds: [
                [inf; WIDTH],
                [inf; WIDTH],
                [inf; WIDTH],
                [neg; WIDTH],
                [neg; WIDTH],
                [neg; WIDTH],
            ],
            child: [LEAF; WIDTH],
        };
        self.out.nodes.push(node);
        let mut depth = 1;
        for (lane, &(k, word)) in lanes.iter().enumerate() {
            let n = &bvh.nodes[k];
            for a in 0..3 {
                node.bounds[a][lane] = n.aabb.min[a];
                node.bounds[a + 3][lane] = n.aabb.max[a];
            }
            match word {
                Some(w) => node.child[lane] = w,
                None => {
                    node.child[lane] = self.out.nodes.len() as u32;
                    depth = depth.max(1 + self.build(k)?);
                }
            }
        }
        self.out.nodes[index] = node;
        Some(depth)
    }
}

impl Bvh8 {
    /// Collapses `bvh`; every binary subtree of at most [`BLOCK`] primitives becomes one leaf
    /// block. Returns the tree and the primitive order its blocks index: `BLOCK` slots per
    /// block, each an index into the primitives `bvh` was built over, a block's unused slots
    /// repeating its last primitive. `is_scalar(i)` says that primitive `i` is no triangle.
    /// `None` when the tree is too deep for the fixed traversal stack (the caller then keeps
    /// another hierarchy).
    pub(crate) fn from_bvh2(
        bvh: &Bvh2,
        is_scalar: impl Fn(u32) -> bool,
    ) -> Option<(Bvh8, Vec<u32>)> {
        if bvh.nodes.is_empty() {
            return None;
        }
        // Primitives under each binary node.
        fn count(bvh: &Bvh2, k: usize, under: &mut [u32]) -> u32 {
            let n = &bvh.nodes[k];
            under[k] = if n.prim_count > 0 {
                n.prim_count
            } else {
                let first = n.first_index as usize;
                count(bvh, first, under) + count(bvh, first + 1, under)
            };
            under[k]
        }
        let mut under = vec![0u32; bvh.nodes.len()];
        count(bvh, 0, &mut under);
        let mut b = Builder {
            bvh,
            under,
            is_scalar: &is_scalar,
            out: Bvh8 { nodes: Vec::new() },
            order: Vec::new(),
        };
        let depth = b.build(0)?;
        // The stack holds at most 3 entries per level (the nearest child is visited directly).
        ((WIDTH - 1) * depth + WIDTH <= STACK).then_some((b.out, b.order))
    }

    /// Closest-hit traversal: `leaf.closest(leaf, &mut t_max)` tests a leaf block and lowers
    /// `t_max` to any hit it finds.
    #[inline(always)]
    pub(crate) fn closest(&self, o: Vec3, d: Vec3, t_max: f32, leaf: &mut impl ClosestLeaf) {
        self.traverse_closest(&BoxRay::new(o, d), t_max, leaf);
    }

    /// Closest-hit traversal of a packet of at most [`PACKET`] rays from origin `o` along
    /// `dirs`: the nodes any of them enters are visited once, front to back by the packet's
    /// entry distance, and culled against the largest of the rays' closest hits so far.
    /// `leaf.closest(leaf, &mut t_max)` tests a leaf block for every ray, lowering each ray's
    /// own closest `t`, and sets `t_max` to the largest of them. Returns `false`, having
    /// traversed nothing, when the directions' signs differ on some axis (the caller then
    /// traces the rays one by one).
    #[inline(always)]
    pub(crate) fn closest_packet(
        &self,
        o: Vec3,
        dirs: &[Vec3],
        t_max: f32,
        leaf: &mut impl ClosestLeaf,
    ) -> bool {
        debug_assert!(!dirs.is_empty() && dirs.len() <= PACKET);
        let Some(ray) = PacketBoxRay::new(o, dirs) else {
            return false;
        };
        self.traverse_closest(&ray, t_max, leaf);
        true
    }

    /// The closest-hit traversal of [`Self::closest`] with the box test `ray`.
    #[inline(always)]
    fn traverse_closest(&self, ray: &impl NodeTest, mut t_max: f32, leaf: &mut impl ClosestLeaf) {
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
                    let t = t_near;
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
                    let mut hits = [(0, 0.0); WIDTH];
                    hits[0] = near;
                    hits[1] = far;
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
                leaf.closest(Leaf::decode(cur), &mut t_max);
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

    /// Any-hit traversal: `leaf.any(leaf, t_max)` returns whether a primitive of the leaf
    /// block is hit; the first `true` ends the traversal.
    #[inline(always)]
    pub(crate) fn any(&self, o: Vec3, d: Vec3, t_max: f32, leaf: &mut impl AnyLeaf) -> bool {
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
                if leaf.any(Leaf::decode(cur), t_max) {
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
