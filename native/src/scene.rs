//! Occlusion queries on a scene of static meshes and moving rigid objects: the compiled twin of
//! geometry/raycast.py's RayScene, on the deterministic BVH (bvh.rs) instead of Embree.
//!
//! As in RayScene, the static meshes are one BVH in the world frame, built once, and each moving
//! object keeps a BVH of its mesh in its local frame: a query moves the ray into the object's
//! frame (o' = A o + b, d' = A d with A = S^-1 R^T, b = -A p, RigidTransform.inverse_matrix's),
//! so the ray parameter t names the same point in both frames and moving an object rebuilds
//! nothing. Each object is skipped when the ray misses its bounding sphere (centre p, radius
//! reach * largest |scale|, reach the farthest local vertex from the local origin grown by
//! RayScene's 1e-6 relative and absolute margin, which dwarfs f64 rounding): a cull that never
//! changes an answer. Objects are visited in the order they were added and the nearest hit is a
//! minimum, so answers do not depend on the order either.

use std::collections::HashMap;

use crate::bvh::{Bvh, Stack};
use crate::rotation::quat_to_matrix;

type Vec3 = [f64; 3];

/// A moving object's placement, RigidTransform's fields: world = position + R(rotation) (scale * local).
pub struct Pose {
    pub position: Vec3,
    pub rotation_xyzw: [f64; 4],
    pub scale: Vec3,
}

/// A moving object: its local BVH and reach, and from its pose the world -> local map and the
/// world bounding sphere.
pub(crate) struct Object {
    pub(crate) bvh: Bvh,
    reach: f64,
    linear: [Vec3; 3],
    translation: Vec3,
    pub(crate) centre: Vec3,
    pub(crate) radius: f64,
    /// A world box [lo, hi] around the object: its local box's corners placed by the pose, grown
    /// by far more than their rounding, and clipped to its bounding sphere's box. Tighter than
    /// the sphere for a long object whose origin is at one end (the demo's obstacles).
    pub(crate) bounds: [Vec3; 2],
}

impl Object {
    /// A, b and the sphere of `pose`, with quat_to_matrix's and inverse_matrix's arithmetic
    /// (the quaternion is used as given, not normalized: RayScene does not normalize it either).
    fn place(&mut self, pose: &Pose) {
        let r = quat_to_matrix(&pose.rotation_xyzw);
        let s = pose.scale;
        self.linear = [0, 1, 2].map(|i| [0, 1, 2].map(|j| r[j][i] / s[i]));
        self.translation = [0, 1, 2].map(|i| -dot(&self.linear[i], &pose.position));
        self.centre = pose.position;
        self.radius = self.reach * s[0].abs().max(s[1].abs()).max(s[2].abs());
        let local = self.bvh.bounds();
        let mut bounds = [[f64::INFINITY; 3], [f64::NEG_INFINITY; 3]];
        for corner in 0..8 {
            let c = [0, 1, 2].map(|a| local[(corner >> a) & 1][a] * s[a]);
            for (i, row) in r.iter().enumerate() {
                let x = pose.position[i] + dot(row, &c);
                bounds[0][i] = bounds[0][i].min(x);
                bounds[1][i] = bounds[1][i].max(x);
            }
        }
        // the corners' rounding and the local frame's (the ray's move into it, the triangle test)
        // are a few 2^-53 of these magnitudes
        let size = (0..3).fold(self.radius, |m, a| {
            m.max(bounds[0][a].abs()).max(bounds[1][a].abs())
        });
        let grow = size * (1.0 / 1073741824.0); // 2^-30
        let sphere = [-self.radius, self.radius].map(|r| self.centre.map(|c| c + r));
        self.bounds = [
            [0, 1, 2].map(|a| bounds[0][a].max(sphere[0][a]) - grow),
            [0, 1, 2].map(|a| bounds[1][a].min(sphere[1][a]) + grow),
        ];
    }

    /// The ray moved into the object's frame.
    pub(crate) fn local(&self, origin: &Vec3, direction: &Vec3) -> (Vec3, Vec3) {
        let a = &self.linear;
        (
            [0, 1, 2].map(|i| dot(&a[i], origin) + self.translation[i]),
            [0, 1, 2].map(|i| dot(&a[i], direction)),
        )
    }

    /// The ray parameter at which o + t d (0 <= t <= t_max) enters the bounding sphere, or None
    /// when it stays outside it.
    pub(crate) fn sphere_entry(&self, origin: &Vec3, direction: &Vec3, t_max: f64) -> Option<f64> {
        let to_centre = sub(&self.centre, origin);
        let squared = dot(direction, direction);
        let r2 = self.radius * self.radius;
        if squared == 0.0 {
            return (dot(&to_centre, &to_centre) <= r2).then_some(0.0);
        }
        // the line's squared distance from the centre as |centre - nearest point|^2, not
        // |to_centre|^2 - along^2 / squared, which cancels for rays from far away
        let nearest = dot(&to_centre, direction) / squared;
        let off = [0, 1, 2].map(|a| to_centre[a] - nearest * direction[a]);
        let inside = r2 - dot(&off, &off);
        if inside < 0.0 {
            return None;
        }
        let half = (inside / squared).sqrt();
        (nearest + half >= 0.0 && nearest - half <= t_max).then_some((nearest - half).max(0.0))
    }
}

fn dot(a: &Vec3, b: &Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn sub(a: &Vec3, b: &Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub struct Scene {
    /// every static triangle, world frame (None: there are none)
    pub(crate) statics: Option<Bvh>,
    index: HashMap<String, usize>,
    pub(crate) objects: Vec<Object>,
}

impl Scene {
    /// The static meshes, each (vertices, faces) with indices in range (the caller checks), as one BVH.
    pub fn new(meshes: &[(Vec<Vec3>, Vec<[u32; 3]>)]) -> Scene {
        let mut vertices = Vec::new();
        let mut faces = Vec::new();
        for (v, f) in meshes {
            let base = vertices.len() as u32;
            faces.extend(f.iter().map(|face| face.map(|i| i + base)));
            vertices.extend_from_slice(v);
        }
        Scene {
            statics: (!faces.is_empty()).then(|| Bvh::new(&vertices, &faces)),
            index: HashMap::new(),
            objects: Vec::new(),
        }
    }

    /// Adds a moving object, mesh in its local frame (indices in range, at least one triangle:
    /// the caller checks). Err: the id is taken.
    pub fn add_dynamic(
        &mut self,
        id: &str,
        vertices: &[Vec3],
        faces: &[[u32; 3]],
        pose: &Pose,
    ) -> Result<(), String> {
        if self.index.contains_key(id) {
            return Err(format!("dynamic object {id:?} already added"));
        }
        let farthest = vertices.iter().map(|v| dot(v, v)).fold(0.0f64, f64::max);
        let mut object = Object {
            bvh: Bvh::new(vertices, faces),
            reach: farthest.sqrt() * (1.0 + 1e-6) + 1e-6,
            linear: [[0.0; 3]; 3],
            translation: [0.0; 3],
            centre: [0.0; 3],
            radius: 0.0,
            bounds: [[0.0; 3]; 2],
        };
        object.place(pose);
        self.index.insert(id.to_owned(), self.objects.len());
        self.objects.push(object);
        Ok(())
    }

    /// Moves an object. Err: no object has that id.
    pub fn set_transform(&mut self, id: &str, pose: &Pose) -> Result<(), String> {
        let row = *self
            .index
            .get(id)
            .ok_or_else(|| format!("no dynamic object {id:?}"))?;
        self.objects[row].place(pose);
        Ok(())
    }

    /// Whether o + t d meets any geometry at some 0 <= t <= t_max.
    pub fn occluded(&self, origin: &Vec3, direction: &Vec3, t_max: f64, stack: &mut Stack) -> bool {
        if let Some(bvh) = &self.statics {
            if bvh.occluded(*origin, *direction, t_max, stack) {
                return true;
            }
        }
        self.objects.iter().any(|object| {
            object.sphere_entry(origin, direction, t_max).is_some() && {
                let (o, d) = object.local(origin, direction);
                object.bvh.occluded(o, d, t_max, stack)
            }
        })
    }

    /// The least t >= 0 at which o + t d meets any geometry (inf: none).
    pub fn first_hit(&self, origin: &Vec3, direction: &Vec3, stack: &mut Stack) -> f64 {
        self.first_hit_within(origin, direction, f64::INFINITY, stack)
    }

    /// first_hit among the hits at 0 <= t <= t_max (inf: none), each tree walked only as far as
    /// the nearest hit so far (Bvh::first_hit_within): first_hit's t wherever that is at most t_max.
    pub fn first_hit_within(
        &self,
        origin: &Vec3,
        direction: &Vec3,
        t_max: f64,
        stack: &mut Stack,
    ) -> f64 {
        let (mut best, mut found) = match &self.statics {
            Some(bvh) => {
                let (t, triangle) = bvh.first_hit_within(*origin, *direction, t_max, stack);
                (t, triangle.is_some())
            }
            None => (t_max, false),
        };
        for object in &self.objects {
            // an object entered beyond the nearest hit so far cannot be nearer
            if object.sphere_entry(origin, direction, best).is_some() {
                let (o, d) = object.local(origin, direction); // affine: the same ray parameter
                if let (t, Some(_)) = object.bvh.first_hit_within(o, d, best, stack) {
                    (best, found) = (t, true); // a hit is never beyond the bound it was given
                }
            }
        }
        if found {
            best
        } else {
            f64::INFINITY
        }
    }
}
