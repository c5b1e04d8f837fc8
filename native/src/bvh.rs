//! A deterministic ray-casting BVH over one triangle soup: the compiled frame path's stand-in for
//! Embree (docs/frame_path.md, "Rust through PyO3"). Embree picks kernels, builders and traversal
//! by CPU at run time, so its hit distances may differ in the last bits between machines; this
//! one gives the same bits on every x86-64 machine for the same inputs:
//!
//! - scalar f64 arithmetic everywhere (the Python reference is float64, and step 3 compares with
//!   it to 1e-9 m; f32 would be no more deterministic, only less precise; node boxes are stored
//!   in f32 rounded outward, to halve the tree's memory, and widened exactly to f64 when tested),
//!   no `mul_add`, no threads, no CPU-specific code; Rust never contracts `a * b + c` into an FMA;
//! - a binned SAH build over the centres of the triangles' boxes, in a fixed order: triangles keep
//!   their index order inside every node (stable partitions; a node whose centres all coincide is
//!   halved in that order), ties between split candidates go to the lowest axis, then lowest bin;
//! - the closest hit is the least (t, triangle index) over all the triangles, the answer of a loop
//!   over every one of them with the same test (tests/native/test_bvh_native.py checks it to the
//!   bit): a box entered at the same t as the best hit is still visited, and no box that holds a
//!   triangle the test meets is culled by rounding (the padding below), so neither the tree's
//!   shape nor the traversal's order changes an answer.
//!
//! The ray/triangle test is Woop, Benthin and Wald's watertight test ("Watertight Ray/Triangle
//! Intersection", JCGT 2(1), 2013, section 3, figure 3's algorithm without backface culling). A
//! vertex is moved into the ray's frame alone (shear so the ray runs along +z), so two triangles
//! that share an edge see its endpoints with the same bits, and the edge function of that edge is
//! the same products in the other order (u = cx by - cy bx against -(bx cy - by cx)): exactly
//! opposite. A ray through the shared edge gets a zero on both sides and hits both, never neither.
//! No epsilon anywhere: an edge function of exactly 0 counts as inside, a determinant of exactly 0
//! (a ray in the triangle's plane, or a degenerate triangle) as a miss. The paper's fallback to
//! double precision when an edge function is 0 in float is moot here: the test already runs in
//! f64. Boxes are met with Ize's conservative slab test ("Robust BVH Ray Traversal", JCGT 2(2),
//! 2013): each slab's exit scaled by 1 + 2 gamma(3), so rounding never culls a box the ray enters.
//! That alone is not enough: the triangle test rounds otherwise than the box test, so a ray through
//! a triangle's edge on its box's face (a floor's edge, a vertex aimed at) may meet the triangle a
//! few units in the last place before it enters the box, or pass outside the box by as little;
//! unpadded, the nearest hit or the lowest index of a tie was missed on about one ray in a
//! thousand aimed at edges. So every box is padded by PAD_SHARE (2^-32) of the largest coordinate
//! magnitude among the triangles and the ray's origin, which bounds the vertices' distances from
//! the origin, and so the triangle test's rounding (a few 2^-53 of it; only a sliver with an edge
//! shorter than about 2^-20 of it could stray further); the padding moves the ray's origin once
//! per ray, not the boxes.
//!
//! Layout, for speed alone (no answer depends on it): the binary SAH tree is collapsed into a
//! 4-wide one, each wide node taking the place of up to four of the binary nodes below one
//! (`collapse`), with their f32 boxes axis by axis in 128 bytes, two aligned cache lines. A ray
//! tests a node's four boxes in one pass, lane by lane, each lane the scalar f64 test (the compiler
//! may run two lanes in one SSE2 instruction: the same IEEE operations, the same bits), and visits
//! those it enters nearest first. A binary box the collapse drops holds its descendants' boxes,
//! and the slab test is monotone in the box, so it could only have culled what theirs cull. On
//! zdm2's 70,691 triangles a random ray visits about 6 wide nodes (the binary tree: about 34 box
//! tests), fetches that mostly miss the caches: latency, not arithmetic, bounds random rays over a
//! whole level. 8 wide (256 bytes a node) measured no faster. Triangles stay three f64 vertices
//! (72 bytes) in leaf order: a ray tests about 2.
//!
//! Distances are ray parameters in units of the direction's length (Embree's convention): the hit
//! point is o + t d. A hit needs 0 <= t <= t_max: a face through the origin is met at t = 0, as
//! Embree's (tnear = 0, inclusive) is.

use std::ops::Range;

/// Triangles per leaf at most (past it a node is split whatever the SAH says), and the fewest a
/// node must hold to be considered for a split. Leaf sizes 4-8 and traversal costs 0.3-1 measured
/// the same on zdm2 (load_tests/bvh_native.py): memory, not the tree's shape, bounds the speed.
const MAX_LEAF: usize = 8;
const MIN_SPLIT: usize = 3;
/// SAH bins per axis: 16 is the usual trade between build time and tree quality.
const BINS: usize = 16;
/// SAH cost of one traversal step relative to one triangle test.
const TRAVERSAL_COST: f64 = 1.0;
/// Ize's 1 + 2 gamma(3) for f64 (unit roundoff 2^-53): the widening of each slab's exit.
const SLAB_WIDEN: f64 = 1.0 + 2.0 * (3.0 * f64::EPSILON * 0.5) / (1.0 - 3.0 * f64::EPSILON * 0.5);
/// The padding of every box, as a share of the largest coordinate's magnitude among the ray's
/// origin and the triangles (2^-32: far above the few roundings of the triangle test, far below
/// any box's size that matters to the speed).
const PAD_SHARE: f64 = 1.0 / 4294967296.0;

#[derive(Clone, Copy)]
struct Aabb {
    lo: [f64; 3],
    hi: [f64; 3],
}

impl Aabb {
    const EMPTY: Aabb = Aabb {
        lo: [f64::INFINITY; 3],
        hi: [f64::NEG_INFINITY; 3],
    };

    fn grow(&mut self, other: &Aabb) {
        for a in 0..3 {
            self.lo[a] = self.lo[a].min(other.lo[a]);
            self.hi[a] = self.hi[a].max(other.hi[a]);
        }
    }

    fn grow_point(&mut self, p: &[f64; 3]) {
        self.grow(&Aabb { lo: *p, hi: *p });
    }

    /// Half the surface area (the SAH only compares areas); 0 for an empty box.
    fn half_area(&self) -> f64 {
        let d = [
            self.hi[0] - self.lo[0],
            self.hi[1] - self.lo[1],
            self.hi[2] - self.lo[2],
        ];
        if d[0] < 0.0 {
            return 0.0;
        }
        d[0] * d[1] + d[1] * d[2] + d[2] * d[0]
    }
}

/// A node of the binary tree the build makes (`collapse` turns it into wide nodes): its box in f32
/// rounded outward, then either a leaf (`count` > 0 triangles from slot `first`) or an inner node
/// (`count` = 0, children at `first` and `first + 1`).
#[derive(Clone, Copy)]
struct Node {
    lo: [f32; 3],
    hi: [f32; 3],
    first: u32,
    count: u32,
}

impl Node {
    const EMPTY: Node = Node {
        lo: [0.0; 3],
        hi: [0.0; 3],
        first: 0,
        count: 0,
    };

    /// The f32 box that holds `bounds`: each bound rounded to the nearest f32, then one step
    /// outward if that went inward (conversions round the same way on every machine).
    fn bound(&mut self, bounds: &Aabb) {
        for a in 0..3 {
            let (lo, hi) = (bounds.lo[a] as f32, bounds.hi[a] as f32);
            self.lo[a] = if lo as f64 > bounds.lo[a] {
                lo.next_down()
            } else {
                lo
            };
            self.hi[a] = if (hi as f64) < bounds.hi[a] {
                hi.next_up()
            } else {
                hi
            };
        }
    }
}

/// A triangle during the build: its box, its box's centre and its index in the input.
struct Prim {
    bounds: Aabb,
    centre: [f64; 3],
    id: u32,
}

/// The traversal's stack of (wide node or first slot, triangle count: 0 for a wide node,
/// parameter at which the ray enters its box), kept by the caller across rays so a batch
/// allocates once.
pub type Stack = Vec<(u32, u32, f64)>;

/// Bounds on what the slab test computes for every ray of a bundle (the segments of one tile of
/// map texels, maps.rs), so that one test of a box for the whole bundle says when none of its rays
/// would enter it: interval arithmetic over the rays (Boulos et al., "Packet-based Whitted and
/// distribution ray tracing", GI 2007, section 3.1), made exact for the computed values rather
/// than the real ones. Every step of `Ray::enters` (a subtraction, a product, a product by
/// SLAB_WIDEN) rounds monotonically in each operand, so over a box of operands its result is least
/// and greatest at corners; the bounds below are those corners computed with the same operations.
/// On an axis the rays go both ways along, those going each way are bounded apart (a box ahead
/// of one group is behind the other), and the bundle misses a box when every combination of the
/// axes' groups does. A box the bundle misses is one `enters` rejects for every ray of the
/// bundle, so skipping it changes no answer. An axis along which some ray's direction is 0, or
/// an inverse not finite, culls nothing.
pub struct Bundle {
    /// Per axis, the rays going + and those going - along it (None: no such ray).
    axes: [[Option<BundleGroup>; 2]; 3],
    /// The largest t_max of the bundle's rays.
    t_max: f64,
}

/// One axis's bounds for the rays going one way along it.
#[derive(Clone, Copy)]
struct BundleGroup {
    negative: bool,
    /// [least, greatest] of the rays' `near_origin`, `far_origin` and `inverse` on this axis.
    near_origin: [f64; 2],
    far_origin: [f64; 2],
    inverse: [f64; 2],
}

impl BundleGroup {
    /// The least near and the greatest far `enters` computes on this axis, for box [lo, hi].
    #[inline(always)]
    fn slab(&self, lo: f64, hi: f64) -> (f64, f64) {
        let (near, far) = if self.negative { (hi, lo) } else { (lo, hi) };
        let [i0, i1] = self.inverse;
        // enters: near = (near - near_origin) * inverse, far = (far - far_origin) * inverse * W
        let (x0, x1) = (near - self.near_origin[1], near - self.near_origin[0]);
        let least = (x0 * i0).min(x0 * i1).min(x1 * i0).min(x1 * i1);
        let (y0, y1) = (far - self.far_origin[1], far - self.far_origin[0]);
        let greatest = (y0 * i0 * SLAB_WIDEN)
            .max(y0 * i1 * SLAB_WIDEN)
            .max(y1 * i0 * SLAB_WIDEN)
            .max(y1 * i1 * SLAB_WIDEN);
        (least, greatest)
    }
}

impl Bundle {
    /// The bundle of `rays` (origin, direction), each cast within its own t_max of at most
    /// `t_max`, on `bvh` (whose reach pads its boxes) or, without one, with no padding.
    pub fn new(
        rays: impl Iterator<Item = ([f64; 3], [f64; 3])>,
        t_max: f64,
        bvh: Option<&Bvh>,
    ) -> Bundle {
        let mut origin = [[f64::INFINITY; 3], [f64::NEG_INFINITY; 3]];
        // per axis: [least, greatest] of the positive directions, of the negative ones; any zero
        let mut ranges = [[[f64::INFINITY, f64::NEG_INFINITY]; 2]; 3];
        let mut zero = [false; 3];
        for (o, d) in rays {
            for a in 0..3 {
                origin[0][a] = origin[0][a].min(o[a]);
                origin[1][a] = origin[1][a].max(o[a]);
                let side = &mut ranges[a][(d[a] < 0.0) as usize];
                side[0] = side[0].min(d[a]);
                side[1] = side[1].max(d[a]);
                zero[a] |= d[a] == 0.0;
            }
        }
        let reach = bvh.map_or(0.0, |bvh| bvh.reach);
        // Ray::new's pad is (reach + the origin's largest |coordinate|) * PAD_SHARE: at most this,
        // at least 0
        let largest = (0..3).fold(0.0f64, |m, a| {
            m.max(origin[0][a].abs()).max(origin[1][a].abs())
        });
        let pad = (reach + largest) * PAD_SHARE;
        let axes = std::array::from_fn(|a| {
            let groups: [_; 2] = std::array::from_fn(|side| {
                let [lo, hi] = ranges[a][side];
                // 1 / d falls as d rises, on either side of 0
                let inverse = [1.0 / hi, 1.0 / lo];
                let (o_lo, o_hi) = (origin[0][a], origin[1][a]);
                let (up, down) = ([o_lo, o_hi + pad], [o_lo - pad, o_hi]);
                // Ray::new: near_origin = origin + pad (- pad when negative), far_origin the other way
                let negative = side == 1;
                let (near_origin, far_origin) = if negative { (down, up) } else { (up, down) };
                // None for no ray going this way; Err for rays it cannot bound
                (lo <= hi).then_some(if inverse.iter().all(|i| i.is_finite()) {
                    Ok(BundleGroup {
                        negative,
                        near_origin,
                        far_origin,
                        inverse,
                    })
                } else {
                    Err(())
                })
            });
            // a group left unbounded would let the other's bounds stand for its rays too
            if zero[a] || groups.iter().any(|g| matches!(g, Some(Err(())))) {
                return [None, None];
            }
            groups.map(|g| g.and_then(Result::ok))
        });
        Bundle { axes, t_max }
    }

    /// Whether no ray of the bundle enters the box [lo, hi] within its t_max (conservatively: a
    /// false answer says nothing).
    pub fn misses(&self, lo: &[f64; 3], hi: &[f64; 3]) -> bool {
        let (mut t0, mut t1) = (0.0f64, self.t_max);
        // the axes the rays go both ways along: each group's (least near, greatest far)
        let mut split = [((0.0, 0.0), (0.0, 0.0)); 3];
        let mut k = 0;
        for a in 0..3 {
            match self.axes[a] {
                [Some(one), None] | [None, Some(one)] => {
                    let (least, greatest) = one.slab(lo[a], hi[a]);
                    t0 = t0.max(least);
                    t1 = t1.min(greatest);
                    if t0 > t1 {
                        return true;
                    }
                }
                [Some(up), Some(down)] => {
                    split[k] = (up.slab(lo[a], hi[a]), down.slab(lo[a], hi[a]));
                    k += 1;
                }
                [None, None] => {}
            }
        }
        // every combination of the split axes' groups must miss
        (0..1usize << k).all(|combination| {
            let (mut c0, mut c1) = (t0, t1);
            for (j, &(up, down)) in split[..k].iter().enumerate() {
                let (least, greatest) = if combination >> j & 1 == 0 { up } else { down };
                c0 = c0.max(least);
                c1 = c1.min(greatest);
            }
            c0 > c1
        })
    }
}

/// A bundle's share of a tree: the wide nodes with a leaf the bundle may enter, and which of their
/// lanes (a bit each), in the order the tree is walked.
pub type Leaves = Vec<(u32, u8)>;

/// Children per wide node.
const WIDTH: usize = 4;

/// A wide node: its children's f32 boxes, axis by axis (`lo[axis][child]`), so one ray's test of
/// all of them runs lane by lane; a child is a wide node (`count` 0, its index in `child`) or a
/// leaf (`count` triangles from slot `child`). Unused lanes hold an empty box (lo +inf, hi -inf),
/// which no ray enters. 128 bytes: two cache lines, aligned.
#[derive(Clone, Copy)]
#[repr(C, align(64))]
struct Wide {
    lo: [[f32; WIDTH]; 3],
    hi: [[f32; WIDTH]; 3],
    child: [u32; WIDTH],
    count: [u32; WIDTH],
}

impl Wide {
    const EMPTY: Wide = Wide {
        lo: [[f32::INFINITY; WIDTH]; 3],
        hi: [[f32::NEG_INFINITY; WIDTH]; 3],
        child: [0; WIDTH],
        count: [0; WIDTH],
    };
}

pub struct Bvh {
    nodes: Vec<Wide>,
    /// Per slot (leaf order): the triangle's three vertices, and its index in the input.
    triangles: Vec<[[f64; 3]; 3]>,
    ids: Vec<u32>,
    /// The largest magnitude of any triangle's coordinate: with the ray's origin, it bounds the
    /// rounding of the triangle test, and so the boxes' padding.
    reach: f64,
}

/// A ray set up once for every test along it: Woop's shear (kx, ky, kz, sx, sy, sz) and the
/// inverse direction for the slab test.
struct Ray {
    origin: [f64; 3],
    /// The origin moved by the boxes' padding (see `enters`), for the near and the far planes.
    near_origin: [f64; 3],
    far_origin: [f64; 3],
    inverse: [f64; 3],
    negative: [bool; 3],
    k: [usize; 3],
    shear: [f64; 3],
}

impl Ray {
    /// None for a zero direction (it meets nothing).
    /// `reach`: the largest coordinate's magnitude of any triangle tested (Bvh::reach).
    #[inline(always)]
    fn new(origin: [f64; 3], direction: [f64; 3], reach: f64) -> Option<Ray> {
        let abs = [direction[0].abs(), direction[1].abs(), direction[2].abs()];
        let kz = if abs[0] >= abs[1] && abs[0] >= abs[2] {
            0
        } else if abs[1] >= abs[2] {
            1
        } else {
            2
        };
        if direction[kz] == 0.0 {
            return None;
        }
        let (mut kx, mut ky) = ((kz + 1) % 3, (kz + 2) % 3);
        if direction[kz] < 0.0 {
            // keeps the winding, so det's sign still tells front from back (not used yet)
            std::mem::swap(&mut kx, &mut ky);
        }
        let inverse = [1.0 / direction[0], 1.0 / direction[1], 1.0 / direction[2]];
        // 1 / -0.0 is -inf: a negative zero goes the negative way, consistently
        let negative = [inverse[0] < 0.0, inverse[1] < 0.0, inverse[2] < 0.0];
        let pad = (reach + origin.iter().fold(0.0f64, |m, x| m.max(x.abs()))) * PAD_SHARE;
        let side = |a: usize, sign: f64| {
            let outward = if negative[a] { -sign } else { sign };
            origin[a] + outward * pad
        };
        Some(Ray {
            origin,
            near_origin: [0, 1, 2].map(|a| side(a, 1.0)),
            far_origin: [0, 1, 2].map(|a| side(a, -1.0)),
            inverse,
            negative,
            k: [kx, ky, kz],
            shear: [
                direction[kx] / direction[kz],
                direction[ky] / direction[kz],
                1.0 / direction[kz],
            ],
        })
    }

    /// Per child of `node`: the parameter at which the ray enters its box, if it meets it within
    /// [0, t_max] (conservatively: see the module's note on Ize's slab test). Each lane is the
    /// scalar test of one box, in the same order of operations whatever the lane.
    #[inline(always)]
    fn enters(&self, node: &Wide, t_max: f64) -> ([f64; WIDTH], [bool; WIDTH]) {
        let (mut t0, mut t1) = ([0.0f64; WIDTH], [t_max; WIDTH]);
        for a in 0..3 {
            let (near, far) = if self.negative[a] {
                (&node.hi[a], &node.lo[a])
            } else {
                (&node.lo[a], &node.hi[a])
            };
            for c in 0..WIDTH {
                // A zero direction component with the origin on the slab's plane gives 0 * inf =
                // NaN: the comparison is false then, so that slab does not cull. (f64::max and min
                // would say the same, at four instructions each instead of one.)
                let near = (near[c] as f64 - self.near_origin[a]) * self.inverse[a];
                let far = (far[c] as f64 - self.far_origin[a]) * self.inverse[a] * SLAB_WIDEN;
                t0[c] = if near > t0[c] { near } else { t0[c] };
                t1[c] = if far < t1[c] { far } else { t1[c] };
            }
        }
        (t0, std::array::from_fn(|c| t0[c] <= t1[c]))
    }

    /// Woop et al.'s watertight test: the ray parameter of the hit, if 0 <= t <= t_max (+0.0 for
    /// -0.0, so a hit at the origin has one sign of zero).
    fn hits(&self, triangle: &[[f64; 3]; 3], t_max: f64) -> Option<f64> {
        let [kx, ky, kz] = self.k;
        let [sx, sy, sz] = self.shear;
        let o = &self.origin;
        let sheared = |v: &[f64; 3]| {
            let (x, y, z) = (v[kx] - o[kx], v[ky] - o[ky], v[kz] - o[kz]);
            (x - sx * z, y - sy * z, sz * z)
        };
        let (ax, ay, az) = sheared(&triangle[0]);
        let (bx, by, bz) = sheared(&triangle[1]);
        let (cx, cy, cz) = sheared(&triangle[2]);
        let u = cx * by - cy * bx;
        let v = ax * cy - ay * cx;
        let w = bx * ay - by * ax;
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 {
            return None;
        }
        let t = (u * az + v * bz + w * cz) / det + 0.0;
        (t >= 0.0 && t <= t_max).then_some(t)
    }
}

impl Bvh {
    /// The BVH of triangles `faces` (indices into `vertices`, all in range: the caller checks).
    pub fn new(vertices: &[[f64; 3]], faces: &[[u32; 3]]) -> Bvh {
        let mut prims: Vec<Prim> = faces
            .iter()
            .enumerate()
            .map(|(id, face)| {
                let mut bounds = Aabb::EMPTY;
                for &index in face {
                    bounds.grow_point(&vertices[index as usize]);
                }
                let centre = [0, 1, 2].map(|a| (bounds.lo[a] + bounds.hi[a]) * 0.5);
                Prim {
                    bounds,
                    centre,
                    id: id as u32,
                }
            })
            .collect();
        let mut nodes = vec![Node::EMPTY];
        let mut scratch: Vec<Prim> = Vec::with_capacity(prims.len());
        // (node, first prim, end prim), depth first: the same order, and so the same tree, every run
        let mut todo = vec![(0usize, 0usize, prims.len())];
        while let Some((node, start, end)) = todo.pop() {
            let span = &mut prims[start..end];
            let mut bounds = Aabb::EMPTY;
            let mut centres = Aabb::EMPTY;
            for p in span.iter() {
                bounds.grow(&p.bounds);
                centres.grow_point(&p.centre);
            }
            nodes[node].bound(&bounds);
            let split = if span.len() < MIN_SPLIT {
                None
            } else {
                split_of(span, &bounds, &centres)
            };
            let mut left_count = match split {
                Some((axis, bin)) => partition(span, &mut scratch, |p| {
                    bin_of(p.centre[axis], &centres, axis) <= bin
                }),
                None => 0,
            };
            if left_count == 0 && span.len() > MAX_LEAF {
                // every centre the same: halves in index order, so no leaf grows past MAX_LEAF
                left_count = span.len() / 2;
            }
            if left_count == 0 {
                nodes[node].first = start as u32;
                nodes[node].count = span.len() as u32;
                continue;
            }
            let left = nodes.len();
            nodes[node].first = left as u32;
            nodes.extend([Node::EMPTY; 2]);
            // right pushed first, so the left subtree is built (and numbered) first
            todo.push((left + 1, start + left_count, end));
            todo.push((left, start, start + left_count));
        }
        let triangles = prims
            .iter()
            .map(|p| faces[p.id as usize].map(|i| vertices[i as usize]))
            .collect();
        let ids = prims.iter().map(|p| p.id).collect();
        let reach = prims.iter().fold(0.0f64, |m, p| {
            (0..3).fold(m, |m, a| {
                m.max(p.bounds.lo[a].abs()).max(p.bounds.hi[a].abs())
            })
        });
        Bvh {
            nodes: collapse(&nodes),
            triangles,
            ids,
            reach,
        }
    }

    /// The box [lo, hi] that holds every triangle (the root's lanes' f32 boxes, which hold them
    /// exactly).
    pub fn bounds(&self) -> [[f64; 3]; 2] {
        let root = &self.nodes[0];
        let mut bounds = [[f64::INFINITY; 3], [f64::NEG_INFINITY; 3]];
        for c in 0..WIDTH {
            for (a, (lo, hi)) in root.lo.iter().zip(&root.hi).enumerate() {
                bounds[0][a] = bounds[0][a].min(lo[c] as f64);
                bounds[1][a] = bounds[1][a].max(hi[c] as f64);
            }
        }
        bounds
    }

    pub fn triangle_count(&self) -> usize {
        self.ids.len()
    }

    /// Whether the ray o + t d meets a triangle at some 0 <= t <= t_max.
    pub fn occluded(
        &self,
        origin: [f64; 3],
        direction: [f64; 3],
        t_max: f64,
        stack: &mut Stack,
    ) -> bool {
        let Some(ray) = Ray::new(origin, direction, self.reach) else {
            return false;
        };
        let mut hit = false;
        self.walk(&ray, t_max, stack, |slots| {
            hit = self.triangles[slots]
                .iter()
                .any(|tri| ray.hits(tri, t_max).is_some());
            (!hit).then_some(t_max)
        });
        hit
    }

    /// The least ray parameter t, 0 <= t <= t_max, at which the ray o + t d meets a triangle, with
    /// the index of that triangle (the lowest of those hit at that t); (t_max, None) when there is
    /// none. Boxes entered beyond t_max, or beyond the nearest hit so far, are not visited, so a
    /// bound (a segment's end, the nearest hit on another tree) saves the walk past it, and an
    /// `occluded` test first would walk the same boxes twice. t_max may be inf.
    pub fn first_hit_within(
        &self,
        origin: [f64; 3],
        direction: [f64; 3],
        t_max: f64,
        stack: &mut Stack,
    ) -> (f64, Option<u32>) {
        let mut best = (t_max, None::<u32>);
        let Some(ray) = Ray::new(origin, direction, self.reach) else {
            return best;
        };
        self.walk(&ray, t_max, stack, |slots| {
            self.nearest_in(&ray, slots, &mut best);
            Some(best.0)
        });
        best
    }

    /// Lowers `best` to the nearest hit among the triangles in `slots`, if nearer (or as near,
    /// with a lower index).
    #[inline(always)]
    fn nearest_in(&self, ray: &Ray, slots: Range<usize>, best: &mut (f64, Option<u32>)) {
        for slot in slots {
            if let Some(t) = ray.hits(&self.triangles[slot], best.0) {
                let id = self.ids[slot];
                // t <= best.0 here: a nearer hit, or one as near with a lower index
                if t < best.0 || best.1.is_none_or(|b| id < b) {
                    *best = (t, Some(id));
                }
            }
        }
    }

    /// Sets `leaves` to the leaves some ray of `bundle` may enter (`Bundle::misses` of each box on
    /// the way down is false), `stack` the walk's.
    pub fn leaves_met(&self, bundle: &Bundle, leaves: &mut Leaves, stack: &mut Vec<u32>) {
        leaves.clear();
        stack.clear();
        stack.push(0);
        while let Some(index) = stack.pop() {
            let node = &self.nodes[index as usize];
            let mut lanes = 0u8;
            for c in 0..WIDTH {
                let lo = [0, 1, 2].map(|a| node.lo[a][c] as f64);
                let hi = [0, 1, 2].map(|a| node.hi[a][c] as f64);
                if lo[0] > hi[0] || bundle.misses(&lo, &hi) {
                    continue; // an unused lane, or a box no ray enters
                }
                if node.count[c] > 0 {
                    lanes |= 1 << c;
                } else {
                    stack.push(node.child[c]);
                }
            }
            if lanes != 0 {
                leaves.push((index, lanes));
            }
        }
    }

    /// first_hit_within for a ray of a bundle whose `leaves` (leaves_met) are given: each leaf's
    /// box is tested for this ray as the walk would, with the nearest hit so far as its bound.
    /// The leaves the bundle misses hold no triangle this ray meets within t_max, and the
    /// nearest hit is a minimum over triangles, so the answer is first_hit_within's, to the bit.
    pub fn first_hit_among(
        &self,
        origin: [f64; 3],
        direction: [f64; 3],
        t_max: f64,
        leaves: &[(u32, u8)],
    ) -> (f64, Option<u32>) {
        let mut best = (t_max, None::<u32>);
        let Some(ray) = Ray::new(origin, direction, self.reach) else {
            return best;
        };
        for &(index, lanes) in leaves {
            let node = &self.nodes[index as usize];
            let (_, met) = ray.enters(node, best.0);
            for (c, met) in met.into_iter().enumerate() {
                if lanes & (1 << c) != 0 && met {
                    let first = node.child[c] as usize;
                    self.nearest_in(&ray, first..first + node.count[c] as usize, &mut best);
                }
            }
        }
        best
    }

    /// Hands `leaf` the slots of every leaf whose box the ray enters within [0, t_max], nearer
    /// boxes first (by entry, the lower lane on a tie). `leaf` returns None to stop, or the new
    /// t_max: boxes entered beyond it are skipped, those entered exactly at it still visited (a
    /// hit there may have a lower triangle index).
    fn walk(
        &self,
        ray: &Ray,
        mut t_max: f64,
        stack: &mut Stack,
        mut leaf: impl FnMut(Range<usize>) -> Option<f64>,
    ) {
        stack.clear();
        stack.push((0, 0, 0.0));
        while let Some((index, count, entry)) = stack.pop() {
            if entry > t_max {
                continue;
            }
            if count > 0 {
                let first = index as usize;
                match leaf(first..first + count as usize) {
                    Some(t) => t_max = t,
                    None => return,
                }
                continue;
            }
            let node = &self.nodes[index as usize];
            let (entries, met) = ray.enters(node, t_max);
            // the children met, nearest first (insertion sort: a tie keeps the lower lane first)
            let mut order = [(0.0f64, 0usize); WIDTH];
            let mut n = 0;
            for c in 0..WIDTH {
                if !met[c] {
                    continue;
                }
                let mut k = n;
                while k > 0 && order[k - 1].0 > entries[c] {
                    order[k] = order[k - 1];
                    k -= 1;
                }
                order[k] = (entries[c], c);
                n += 1;
            }
            for &(entry, c) in order[..n].iter().rev() {
                stack.push((node.child[c], node.count[c], entry));
            }
        }
    }
}

/// The wide tree of a binary one (`nodes[0]` its root), the same leaves in the same slots: each
/// wide node takes the place of a binary node and its descendants down to WIDTH of them, opened
/// largest box first (the lowest lane on a tie), in left-to-right order. A box dropped between a
/// wide node and its children holds theirs, so no ray that meets a child is kept from it.
/// Numbered depth first, a node's first inner child right after it.
fn collapse(binary: &[Node]) -> Vec<Wide> {
    let mut nodes = Vec::new();
    // (the wide node and lane that point to the new node, the binary node whose place it takes)
    let mut todo: Vec<(Option<(usize, usize)>, usize)> = vec![(None, 0)];
    while let Some((parent, index)) = todo.pop() {
        let wide = nodes.len();
        nodes.push(Wide::EMPTY);
        if let Some((parent, lane)) = parent {
            nodes[parent].child[lane] = wide as u32;
        }
        let mut children = vec![index];
        while children.len() < WIDTH {
            let mut widest: Option<(f64, usize)> = None;
            for (lane, &child) in children.iter().enumerate() {
                let node = &binary[child];
                if node.count == 0 {
                    let area = Aabb {
                        lo: node.lo.map(f64::from),
                        hi: node.hi.map(f64::from),
                    }
                    .half_area();
                    if widest.is_none_or(|(a, _)| area > a) {
                        widest = Some((area, lane));
                    }
                }
            }
            let Some((_, lane)) = widest else { break };
            let first = binary[children[lane]].first as usize;
            children.splice(lane..=lane, [first, first + 1]);
        }
        // inner children pushed last lane first, so the lowest lane's subtree comes next
        for (lane, &child) in children.iter().enumerate().rev() {
            let node = &binary[child];
            for a in 0..3 {
                nodes[wide].lo[a][lane] = node.lo[a];
                nodes[wide].hi[a][lane] = node.hi[a];
            }
            if node.count > 0 {
                nodes[wide].child[lane] = node.first;
                nodes[wide].count[lane] = node.count;
            } else {
                todo.push((Some((wide, lane)), child));
            }
        }
    }
    nodes
}

/// The bin of a centre along an axis, 0..BINS, from the node's centre bounds.
fn bin_of(centre: f64, centres: &Aabb, axis: usize) -> usize {
    let extent = centres.hi[axis] - centres.lo[axis];
    let bin = ((centre - centres.lo[axis]) * (BINS as f64 / extent)) as usize;
    bin.min(BINS - 1)
}

/// The binned SAH's best split of a node: (axis, last bin of the left side), or None when no
/// split costs less than a leaf of `MAX_LEAF` or fewer triangles (or every centre is the same).
fn split_of(span: &[Prim], bounds: &Aabb, centres: &Aabb) -> Option<(usize, usize)> {
    let mut best: Option<(f64, usize, usize)> = None;
    for axis in 0..3 {
        if centres.hi[axis] - centres.lo[axis] <= 0.0 {
            continue;
        }
        let mut counts = [0usize; BINS];
        let mut boxes = [Aabb::EMPTY; BINS];
        for p in span {
            let bin = bin_of(p.centre[axis], centres, axis);
            counts[bin] += 1;
            boxes[bin].grow(&p.bounds);
        }
        // area * count of the left side for each split after bin i, then the right side's added
        let mut costs = [0.0f64; BINS - 1];
        let (mut side, mut count) = (Aabb::EMPTY, 0usize);
        for i in 0..BINS - 1 {
            side.grow(&boxes[i]);
            count += counts[i];
            costs[i] = side.half_area() * count as f64;
        }
        let (mut side, mut count) = (Aabb::EMPTY, 0usize);
        for i in (0..BINS - 1).rev() {
            side.grow(&boxes[i + 1]);
            count += counts[i + 1];
            costs[i] += side.half_area() * count as f64;
        }
        for (bin, &cost) in costs.iter().enumerate() {
            if best.is_none_or(|(b, _, _)| cost < b) {
                best = Some((cost, axis, bin));
            }
        }
    }
    let (cost, axis, bin) = best?;
    let area = bounds.half_area();
    let split_cost = TRAVERSAL_COST + if area > 0.0 { cost / area } else { 0.0 };
    // a leaf costs one test per triangle; past MAX_LEAF the split is taken whatever it costs
    (split_cost < span.len() as f64 || span.len() > MAX_LEAF).then_some((axis, bin))
}

/// Moves the prims for which `left` holds to the front, both sides in their former order (so
/// ties keep index order); returns how many. Returns 0 when either side would be empty.
fn partition(span: &mut [Prim], scratch: &mut Vec<Prim>, left: impl Fn(&Prim) -> bool) -> usize {
    let count = span.iter().filter(|p| left(p)).count();
    if count == 0 || count == span.len() {
        return 0;
    }
    scratch.clear();
    scratch.extend(span.iter().filter(|p| left(p)).map(copy_prim));
    scratch.extend(span.iter().filter(|p| !left(p)).map(copy_prim));
    for (slot, p) in span.iter_mut().zip(scratch.drain(..)) {
        *slot = p;
    }
    count
}

fn copy_prim(p: &Prim) -> Prim {
    Prim {
        bounds: p.bounds,
        centre: p.centre,
        id: p.id,
    }
}
