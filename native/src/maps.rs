//! The S-maps and V-maps of target sample points over a window of Toric texture space, by ray
//! casting (the occlusion-anticipation paper, section 4.1.1, the target shadow map, and 4.1.2,
//! the occluder velocity map): the twin of geometry/toric_maps/embree.py's
//! `EmbreeMapBackend.compute`, on the Scene (scene.rs) and its deterministic BVH instead of Embree.
//!
//! For each sample point s and each texel, one segment from s to the texel's torus point P,
//! starting SAMPLE_CLEARANCE_M from s and stopping SEGMENT_END_MARGIN short of P
//! (geometry/toric_maps/base.py says why): the S-map is whether it meets anything but the
//! sample's own object, the V-map the first hit's rigid velocity v + w x (p - c) minus the torus
//! point's velocity (by finite difference at fixed (theta, phi), when the previous torus is
//! given), in Toric angular rates, and the depth the distance from s to that hit. Embree casts
//! in float32, this in float64: a texel may differ within rounding of an edge, a velocity or a
//! depth by float32's rounding of the hit point.
//!
//! The segments are cast a tile of TILE_ROWS x TILE_COLUMNS texels at a time. One bundle test
//! (bvh.rs `Bundle`) per box finds the static leaves any of a tile's segments may enter and the
//! moving objects whose world boxes (scene.rs `bounds`) any may enter; each segment is then cast
//! against those alone, and a tile that may meet nothing casts no segment. On the demo scene most tiles
//! meet nothing. A moving object whose bounding sphere misses the box around all of one sample's
//! segments is left out of that sample's tiles. Neither cull changes an answer: the maps are the
//! bits each segment's own walk of the whole scene gives (tests/native/test_map_tiles_native.py).

use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

use crate::amap::Window;
use crate::bvh::{Bundle, Leaves, Stack};
use crate::rotation::Vec3;
use crate::scene::Scene;
use crate::toric::{arc_sincos, tangent_frame_of, torus_position_of, Torus};

/// base.py's SEGMENT_END_MARGIN (a share of s -> P) and SAMPLE_CLEARANCE_M (metres).
pub const SEGMENT_END_MARGIN: f64 = 1e-4;
pub const SAMPLE_CLEARANCE_M: f64 = 1e-3;

/// A moving object's motion for the V-map (DynamicOccluder): where its origin is, world metres,
/// its linear velocity, m/s, and its angular velocity about that origin, rad/s, world frame.
pub struct Motion {
    pub position: Vec3,
    pub linear: Vec3,
    pub angular: Vec3,
}

/// One sample point and the index of the moving object it ignores (its own target), if any.
pub struct Sample {
    pub point: Vec3,
    pub ignores: Option<usize>,
}

/// ShadowVelocityMaps' arrays, k maps of res x res texels, row-major per map: shadow 0 or 1,
/// velocity (d theta/dt, d phi/dt) rad/s, depth metres (inf where not occluded).
pub struct Maps {
    pub shadow: Vec<f32>,
    pub velocity: Vec<[f32; 2]>,
    pub depth: Vec<f32>,
}

fn sub(a: &Vec3, b: &Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: &Vec3, b: &Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(u: &Vec3, v: &Vec3) -> Vec3 {
    [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ]
}

/// The sines and cosines of a window's texel centres: arc_sincos of each row's theta on `torus`
/// (row-major: texel t is in row t / n), sincos of each column's phi. The texels read these, one
/// pair per row and per column rather than two per texel: on the demo scene's maps the sincos
/// calls were about a sixth of a map's time (perf), for the same bits.
struct TexelAngles {
    theta: Vec<(f64, f64)>,
    phi: Vec<(f64, f64)>,
}

fn centre(min: f64, step: f64, k: usize) -> f64 {
    min + (k as f64 + 0.5) * step
}

/// arc_sincos of each texel row's theta on `torus`.
fn theta_rows(torus: &Torus, window: &Window) -> Vec<(f64, f64)> {
    (0..window.resolution)
        .map(|i| {
            arc_sincos(
                torus,
                centre(window.theta_min_rad, window.theta_step_rad, i),
            )
        })
        .collect()
}

impl TexelAngles {
    fn of(torus: &Torus, window: &Window) -> Self {
        TexelAngles {
            theta: theta_rows(torus, window),
            phi: (0..window.resolution)
                .map(|j| libm::sincos(centre(window.phi_min_rad, window.phi_step_rad, j)))
                .collect(),
        }
    }

    /// Texel t's (theta, phi) sines and cosines, t row-major; `theta` another torus's rows
    /// (theta_rows) where given, the phi columns being the same on every torus.
    fn at(&self, t: usize, theta: Option<&[(f64, f64)]>) -> ((f64, f64), (f64, f64)) {
        let n = self.phi.len();
        (theta.unwrap_or(&self.theta)[t / n], self.phi[t % n])
    }
}

/// The texel centres' torus points, row-major.
fn torus_points(torus: &Torus, angles: &TexelAngles) -> Vec<Vec3> {
    (0..angles.theta.len() * angles.phi.len())
        .map(|t| {
            let (theta, phi) = angles.at(t, None);
            torus_position_of(torus, theta, phi)
        })
        .collect()
}

/// Whether the sphere (centre, radius) meets the box [lo, hi].
fn sphere_meets_box(centre: &Vec3, radius: f64, lo: &Vec3, hi: &Vec3) -> bool {
    let gap: f64 = (0..3)
        .map(|a| {
            let d = (lo[a] - centre[a]).max(centre[a] - hi[a]).max(0.0);
            d * d
        })
        .sum();
    gap <= radius * radius
}

/// Texel rows and columns of a tile, whose segments are culled together: small enough that its
/// segments' bundle is narrow, large enough that its tests are shared by many segments (8 x 8
/// measured fastest over the demo session's maps, tests/native/test_map_tiles_native.py's and
/// two levels', against 4 x 4, 8 x 16 and 16 x 16: docs/frame_path.md).
const TILE_ROWS: usize = 8;
const TILE_COLUMNS: usize = 8;

/// One segment of the maps (module docstring): from `start`, SAMPLE_CLEARANCE_M past the sample
/// point, along `rel` (the sample to the texel's torus point), ray parameter in [0, t_limit].
#[derive(Clone, Copy)]
struct Segment {
    rel: Vec3,
    length: f64,
    t_start: f64,
    start: Vec3,
    t_limit: f64,
}

impl Segment {
    fn of(s: &Vec3, p: &Vec3) -> Segment {
        let rel = sub(p, s);
        let length = dot(&rel, &rel).sqrt();
        let t_start = (SAMPLE_CLEARANCE_M / length.max(1e-12)).min(0.5);
        Segment {
            rel,
            length,
            t_start,
            start: [0, 1, 2].map(|a| s[a] + rel[a] * t_start),
            t_limit: (1.0 - SEGMENT_END_MARGIN) - t_start,
        }
    }
}

/// Threads one call may use (set_threads); 1 until a process says otherwise.
static THREADS: AtomicUsize = AtomicUsize::new(1);
/// Texels a thread takes at least: below, a thread's start costs more than it saves.
const TEXELS_PER_THREAD_MIN: usize = 512;

thread_local! {
    /// The calling thread's own count (set_threads_here), over THREADS.
    static THREADS_HERE: Cell<Option<usize>> = const { Cell::new(None) };
}

/// How many threads each later call may share its texels among (1: the caller's alone). Every
/// texel is computed the same way whichever thread takes it, so the maps' bits do not depend on it.
pub fn set_threads(threads: usize) {
    THREADS.store(threads.max(1), Ordering::Relaxed);
}

/// set_threads for the calling thread's later calls alone: a thread computing maps beside the
/// one that answers frames keeps to its own core (compiled_maps.py's maps thread).
pub fn set_threads_here(threads: usize) {
    THREADS_HERE.with(|here| here.set(Some(threads.max(1))));
}

/// The previous torus, its rows' sines and cosines (its alpha differs) and dt_s, for the torus
/// points' own velocity.
type Before<'a> = (&'a Torus, Vec<(f64, f64)>, f64);

/// A thread's buffers, kept across its tiles.
#[derive(Default)]
struct Scratch {
    tile: Vec<usize>,
    segments: Vec<Segment>,
    leaves: Leaves,
    nodes: Vec<u32>,
    objects: Vec<usize>,
    stack: Stack,
}

/// What every texel of one call reads, worked out once.
struct Call<'a> {
    scene: &'a Scene,
    motions: &'a [Motion],
    torus: &'a Torus,
    samples: &'a [Sample],
    angles: TexelAngles,
    points: Vec<Vec3>, // the texels' torus points, row-major
    before: Option<Before<'a>>,
    near: Vec<Vec<usize>>, // by sample: the moving objects its segments may meet
}

/// The maps' texels from `from` on (index: sample * texels + texel), as many as the slices hold.
struct Texels<'m> {
    from: usize,
    shadow: &'m mut [f32],
    velocity: &'m mut [[f32; 2]],
    depth: &'m mut [f32],
}

impl Texels<'_> {
    /// The first `n` texels, and the rest.
    fn split(self, n: usize) -> (Self, Self) {
        let (shadow, shadow_rest) = self.shadow.split_at_mut(n);
        let (velocity, velocity_rest) = self.velocity.split_at_mut(n);
        let (depth, depth_rest) = self.depth.split_at_mut(n);
        (
            Texels {
                from: self.from,
                shadow,
                velocity,
                depth,
            },
            Texels {
                from: self.from + n,
                shadow: shadow_rest,
                velocity: velocity_rest,
                depth: depth_rest,
            },
        )
    }
}

/// The maps of `samples` over `window` of `torus` (EmbreeMapBackend.compute); `motions` one per
/// moving object of `scene`, in its order; `previous`: the torus dt_s earlier, for the torus
/// points' own velocity (none: the torus is taken as still). The texels are shared among up to
/// set_threads' threads, in contiguous runs.
pub fn shadow_velocity_maps(
    scene: &Scene,
    motions: &[Motion],
    torus: &Torus,
    window: &Window,
    samples: &[Sample],
    previous: Option<(&Torus, f64)>,
) -> Maps {
    let angles = TexelAngles::of(torus, window);
    let points = torus_points(torus, &angles);
    let before = previous.map(|(before, dt_s)| (before, theta_rows(before, window), dt_s));
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in &points {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let near = samples
        .iter()
        .map(|sample| {
            let s = &sample.point;
            let (lo, hi) = (
                [0, 1, 2].map(|a| lo[a].min(s[a])),
                [0, 1, 2].map(|a| hi[a].max(s[a])),
            );
            (0..scene.objects.len())
                .filter(|&i| sample.ignores != Some(i))
                .filter(|&i| {
                    sphere_meets_box(&scene.objects[i].centre, scene.objects[i].radius, &lo, &hi)
                })
                .collect()
        })
        .collect();
    let call = Call {
        scene,
        motions,
        torus,
        samples,
        angles,
        points,
        before,
        near,
    };
    let n = samples.len() * call.points.len();
    let mut maps = Maps {
        shadow: vec![0.0; n],
        velocity: vec![[0.0; 2]; n],
        depth: vec![f32::INFINITY; n],
    };
    let all = Texels {
        from: 0,
        shadow: &mut maps.shadow,
        velocity: &mut maps.velocity,
        depth: &mut maps.depth,
    };
    let threads = THREADS_HERE
        .with(Cell::get)
        .unwrap_or_else(|| THREADS.load(Ordering::Relaxed))
        .min(n / TEXELS_PER_THREAD_MIN)
        .max(1);
    if threads == 1 {
        call.fill(all);
    } else {
        // runs of whole bands (a sample's TILE_ROWS texel rows), so no tile is split
        let bands: Vec<usize> = (0..samples.len())
            .flat_map(|_| (0..window.resolution).step_by(TILE_ROWS))
            .map(|row| TILE_ROWS.min(window.resolution - row) * window.resolution)
            .collect();
        let per_thread = bands.len().div_ceil(threads);
        std::thread::scope(|scope| {
            let mut rest = all;
            for mine in bands.chunks(per_thread).take(threads - 1) {
                let (mine, others) = rest.split(mine.iter().sum());
                let call = &call;
                scope.spawn(move || call.fill(mine));
                rest = others;
            }
            call.fill(rest); // the last run, on the caller's thread
        });
    }
    maps
}

impl Call<'_> {
    /// Computes `texels` (module docstring), which are whole bands of TILE_ROWS rows of a sample's
    /// texels (the last band of a map may be fewer rows), a tile at a time.
    fn fill(&self, mut texels: Texels<'_>) {
        let (m, res) = (self.points.len(), self.angles.phi.len());
        let mut scratch = Scratch::default();
        let n = texels.shadow.len();
        let mut done = 0;
        while done < n {
            let (k, first) = ((texels.from + done) / m, (texels.from + done) % m);
            let rows = first / res..(first / res + TILE_ROWS).min(res);
            for column in (0..res).step_by(TILE_COLUMNS) {
                let columns = column..(column + TILE_COLUMNS).min(res);
                let tile = rows
                    .clone()
                    .flat_map(|r| columns.clone().map(move |c| r * res + c));
                scratch.tile.clear();
                scratch.tile.extend(tile);
                self.tile(k, done - first, &mut texels, &mut scratch);
            }
            done += rows.len() * res;
        }
    }

    /// The texels `scratch.tile` (row-major indices into a map) of sample `k`'s map, written at
    /// `offset` + texel in `texels`: its segments culled together, then each cast against what is
    /// left.
    fn tile(&self, k: usize, offset: usize, texels: &mut Texels<'_>, scratch: &mut Scratch) {
        let (s, near) = (&self.samples[k].point, &self.near[k][..]);
        scratch.segments.clear();
        scratch.segments.extend(
            scratch
                .tile
                .iter()
                .map(|&texel| Segment::of(s, &self.points[texel])),
        );
        let t_max = scratch
            .segments
            .iter()
            .fold(0.0f64, |m, segment| m.max(segment.t_limit));
        let statics = self.scene.statics.as_ref();
        let rays = scratch
            .segments
            .iter()
            .map(|segment| (segment.start, segment.rel));
        let bundle = Bundle::new(rays, t_max, statics);
        if let Some(bvh) = statics {
            bvh.leaves_met(&bundle, &mut scratch.leaves, &mut scratch.nodes);
        }
        scratch.objects.clear();
        scratch.objects.extend(near.iter().copied().filter(|&i| {
            let [lo, hi] = &self.scene.objects[i].bounds;
            !bundle.misses(lo, hi)
        }));
        if scratch.leaves.is_empty() && scratch.objects.is_empty() {
            return; // no segment of the tile meets anything: the maps' defaults
        }
        for (segment, &texel) in scratch.segments.iter().zip(&scratch.tile) {
            if let Some(hit) = self.texel(
                s,
                segment,
                texel,
                &scratch.leaves,
                &scratch.objects,
                &mut scratch.stack,
            ) {
                let at = offset + texel;
                (texels.shadow[at], texels.velocity[at], texels.depth[at]) = (1.0, hit.0, hit.1);
            }
        }
    }

    /// `segment` from sample point `s` to the texel's torus point, against the static `leaves`
    /// and the moving `objects` its tile may meet: its V-map value and depth, None when it meets
    /// nothing.
    #[inline(always)]
    fn texel(
        &self,
        s: &Vec3,
        segment: &Segment,
        texel: usize,
        leaves: &[(u32, u8)],
        objects: &[usize],
        stack: &mut Stack,
    ) -> Option<([f32; 2], f32)> {
        let (scene, motions, torus) = (self.scene, self.motions, self.torus);
        let Segment {
            rel,
            length,
            t_start,
            start,
            t_limit,
        } = *segment;
        let mut best = t_limit;
        let mut object = None;
        if let (Some(bvh), false) = (&scene.statics, leaves.is_empty()) {
            best = bvh.first_hit_among(start, rel, t_limit, leaves).0;
        }
        for &i in objects {
            let o = &scene.objects[i];
            if o.sphere_entry(&start, &rel, best).is_some() {
                let (origin, direction) = o.local(&start, &rel);
                // o.local is affine: the local ray's parameter is the world one's
                let t = o.bvh.first_hit_within(origin, direction, best, stack).0;
                if t < best {
                    (best, object) = (t, Some(i));
                }
            }
        }
        if best >= t_limit {
            return None;
        }
        let t_total = t_start + best;
        let mut velocity = match object {
            Some(i) => {
                let hit = [0, 1, 2].map(|a| s[a] + rel[a] * t_total);
                let spin = cross(&motions[i].angular, &sub(&hit, &motions[i].position));
                [0, 1, 2].map(|a| motions[i].linear[a] + spin[a])
            }
            None => [0.0; 3],
        };
        let (theta, phi) = self.angles.at(texel, None);
        if let Some((before, before_rows, dt_s)) = &self.before {
            let (before_theta, before_phi) = self.angles.at(texel, Some(before_rows));
            let moved = sub(
                &self.points[texel],
                &torus_position_of(before, before_theta, before_phi),
            );
            velocity = [0, 1, 2].map(|a| velocity[a] - moved[a] / dt_s);
        }
        let [d_theta, d_phi, _] = tangent_frame_of(torus, theta, phi);
        let n_phi = dot(&d_phi, &d_phi);
        let v_phi = if n_phi > 1e-18 {
            dot(&velocity, &d_phi) / n_phi
        } else {
            0.0
        };
        Some((
            [
                (dot(&velocity, &d_theta) / dot(&d_theta, &d_theta)) as f32,
                v_phi as f32,
            ],
            (t_total * length) as f32,
        ))
    }
}
