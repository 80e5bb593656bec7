//! Closed triangle meshes as 3D walls and bodies: checked (closed, consistently oriented, facing out),
//! with an exact signed distance, the feet of a particle on the faces in reach, and boundary points
//! sampled uniformly on the surface.
//!
//! - Nearest points come from parry's bounding-volume hierarchy over the triangles; the sign of the
//!   distance from the angle-weighted pseudo-normal of the nearest feature (face, edge or vertex), which
//!   is exact for a closed mesh (Bærentzen & Aanæs 2005, "Signed distance computation using the angle
//!   weighted pseudonormal").
//! - Creases: an edge whose faces' normals differ by more than the crease angle is a crease; its points
//!   carry both faces' normals, and a vertex where three or more distinct normals meet is a corner with
//!   three (as a box's edges and corners, [`crate::wall::Normals`]). Elsewhere the surface is smooth and
//!   a point carries its face's normal.
//! - Boundary points: Poisson-disk elimination. Candidates are laid on every triangle at most `spacing/4`
//!   apart (a barycentric lattice), and on the crease edges and corners; taken corners first, then crease
//!   points, then faces, a candidate is kept unless a kept point lies within `3/4 spacing`. Every surface
//!   point is then within `spacing` of a kept one, and kept points are at least `3/4 spacing` apart
//!   however finely or coarsely the mesh is triangulated.
//!
//! The mesh is held in double precision in either precision of the engine.

use parry3d_f64::bounding_volume::Aabb;
use parry3d_f64::na::{Point3, Vector3};
use parry3d_f64::query::PointQueryWithLocation;
use parry3d_f64::shape::{TriMesh, TrianglePointLocation};
use std::collections::HashMap;

type V = Vector3<f64>;

/// A closed, consistently oriented triangle mesh whose triangles face out (counter-clockwise seen from
/// outside), placed in the scene.
pub struct TriangleMesh {
    vertices: Vec<V>,
    triangles: Vec<[u32; 3]>,
    /// Unit outward normal of each triangle.
    normals: Vec<V>,
    /// Pseudo-normal of each triangle's edges `k` (from vertex `k` to `k + 1`): the sum of the two
    /// faces' normals, normalised.
    edge_normals: Vec<[V; 3]>,
    /// Angle-weighted pseudo-normal of each vertex.
    vertex_normals: Vec<V>,
    /// The triangle on the other side of each triangle's edge `k`.
    neighbours: Vec<[u32; 3]>,
    /// cos of the crease angle: faces whose normals' dot product is below it meet at a crease.
    crease_cos: f64,
    /// The bounding-volume hierarchy of the triangles.
    tree: TriMesh,
    /// Enclosed volume (m³) and surface area (m²).
    volume: f64,
    area: f64,
    /// Length (m) of the diagonal of the bounding box: the scale of rounding.
    size: f64,
    /// The bounding box's lowest and highest corners (m).
    lo: V,
    hi: V,
}

impl std::fmt::Debug for TriangleMesh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "TriangleMesh {{ {} vertices, {} triangles }}", self.vertices.len(), self.triangles.len())
    }
}

impl PartialEq for TriangleMesh {
    fn eq(&self, other: &Self) -> bool {
        self.vertices == other.vertices && self.triangles == other.triangles && self.crease_cos == other.crease_cos
    }
}

/// Why a mesh was refused: the key it concerns (`vertices` or `triangles`) and the reason.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshError {
    pub key: &'static str,
    pub reason: String,
}

fn refuse<T>(key: &'static str, reason: impl Into<String>) -> Result<T, MeshError> {
    Err(MeshError { key, reason: reason.into() })
}

/// Candidate feet of one particle (foot, normal into the wall, distance), the nearest [`Feet::MOST`].
struct Feet {
    found: [(V, V, f64); Feet::MOST],
    len: usize,
}

impl Default for Feet {
    fn default() -> Self {
        Self { found: [(V::zeros(), V::zeros(), f64::INFINITY); Feet::MOST], len: 0 }
    }
}

impl Feet {
    const MOST: usize = 16;

    /// Adds a foot, or replaces the farthest when full and it is nearer.
    fn offer(&mut self, q: V, n: V, d: f64) {
        if self.len < Self::MOST {
            self.found[self.len] = (q, n, d);
            self.len += 1;
        } else if let Some(far) = (0..Self::MOST).max_by(|&a, &b| self.found[a].2.total_cmp(&self.found[b].2)) {
            if self.found[far].2 > d {
                self.found[far] = (q, n, d);
            }
        }
    }

    /// Gives `add` the feet nearest first, each unless a foot given before has a normal within the angle
    /// whose cosine is `cos` of its own.
    fn keep_distinct(mut self, cos: f64, mut add: impl FnMut(V, V)) {
        let found = &mut self.found[..self.len];
        found.sort_by(|a, b| a.2.total_cmp(&b.2));
        let mut kept = [V::zeros(); Self::MOST];
        let mut count = 0;
        for &(q, n, _) in found.iter() {
            if kept[..count].iter().all(|m| m.dot(&n) < cos) {
                kept[count] = n;
                count += 1;
                add(q, n);
            }
        }
    }
}

/// Where a point of a triangle lies, from its barycentric coordinates: on a vertex, an edge or the face.
enum Feature {
    Vertex(usize),
    /// Local edge `k` (from vertex `k` to `k + 1`).
    Edge(usize),
    Face,
}

impl TriangleMesh {
    /// Checks and builds a mesh from its vertices (m) and triangles (indices into `vertices`,
    /// counter-clockwise seen from outside). Vertices at the same position are one vertex (an STL file
    /// repeats them). Refused: fewer than 4 triangles, a non-finite coordinate, an index out of range,
    /// a triangle without area, an edge not shared by exactly two triangles that run it in opposite
    /// directions (an open or inconsistently oriented mesh), a negative volume (triangles facing in).
    /// Self-intersections are not looked for.
    pub fn new(vertices: &[[f64; 3]], triangles: &[[usize; 3]], crease_angle: f64) -> Result<Self, MeshError> {
        Self::build(vertices, triangles, crease_angle, true)
    }

    /// A mesh of any triangles, open or closed, oriented or not (a thin wall's middle surface,
    /// [`TriangleMesh::shell_distance`]): checked as [`TriangleMesh::new`] but for closedness, orientation
    /// and volume.
    pub fn open(vertices: &[[f64; 3]], triangles: &[[usize; 3]]) -> Result<Self, MeshError> {
        Self::build(vertices, triangles, std::f64::consts::PI, false)
    }

    fn build(
        vertices: &[[f64; 3]],
        triangles: &[[usize; 3]],
        crease_angle: f64,
        closed: bool,
    ) -> Result<Self, MeshError> {
        let least = if closed { 4 } else { 1 };
        if triangles.len() < least {
            let what = if closed { "a closed mesh" } else { "a mesh" };
            return refuse("triangles", format!("{what} needs at least {least} triangles, got {}", triangles.len()));
        }
        if let Some(i) = vertices.iter().position(|v| v.iter().any(|c| !c.is_finite())) {
            return refuse("vertices", format!("vertices[{i}] is not finite"));
        }
        // One index per position: sort by coordinates, number the distinct ones.
        let mut order: Vec<usize> = (0..vertices.len()).collect();
        order.sort_by(|&a, &b| vertices[a].partial_cmp(&vertices[b]).expect("finite"));
        let mut welded = vec![0u32; vertices.len()];
        let mut points: Vec<V> = Vec::new();
        for (k, &i) in order.iter().enumerate() {
            if k == 0 || vertices[i] != vertices[order[k - 1]] {
                points.push(V::from(vertices[i]));
            }
            welded[i] = (points.len() - 1) as u32;
        }
        let mut tris = Vec::with_capacity(triangles.len());
        for (t, tri) in triangles.iter().enumerate() {
            if let Some(&i) = tri.iter().find(|&&i| i >= vertices.len()) {
                return refuse("triangles", format!("triangles[{t}] names vertex {i}; there are {}", vertices.len()));
            }
            tris.push(tri.map(|i| welded[i]));
        }
        // The bounding box of the vertices the triangles use (a file may list others).
        let used = || tris.iter().flatten().map(|&i| &points[i as usize]);
        let lo = used().fold(V::repeat(f64::INFINITY), |m, p| m.inf(p));
        let hi = used().fold(V::repeat(f64::NEG_INFINITY), |m, p| m.sup(p));
        let size = (hi - lo).norm();
        let mut normals = Vec::with_capacity(tris.len());
        for (t, tri) in tris.iter().enumerate() {
            let [a, b, c] = tri.map(|i| points[i as usize]);
            let n = (b - a).cross(&(c - a));
            if n.norm() <= 1e-12 * size * size {
                return refuse("triangles", format!("triangles[{t}] has no area (its corners are on one line)"));
            }
            normals.push(n.normalize());
        }
        // Closed: each directed edge once, and its reverse once (closed and consistently oriented). Open:
        // triangles that share an edge are neighbours; a triangle is its own across an edge it alone has.
        let mut neighbours: Vec<[u32; 3]> = (0..tris.len()).map(|t| [t as u32; 3]).collect();
        let mut volume = 0.0;
        if closed {
            let mut edges: HashMap<(u32, u32), (u32, usize)> = HashMap::with_capacity(3 * tris.len());
            for (t, tri) in tris.iter().enumerate() {
                for k in 0..3 {
                    let e = (tri[k], tri[(k + 1) % 3]);
                    if let Some((other, _)) = edges.insert(e, (t as u32, k)) {
                        return refuse(
                            "triangles",
                            format!(
                                "triangles[{other}] and triangles[{t}] both run from vertex {} to {}: the mesh is \
                                 not consistently oriented, or more than two triangles meet at an edge",
                                e.0, e.1
                            ),
                        );
                    }
                }
            }
            for (t, tri) in tris.iter().enumerate() {
                for k in 0..3 {
                    let (a, b) = (tri[k], tri[(k + 1) % 3]);
                    match edges.get(&(b, a)) {
                        Some(&(other, _)) => neighbours[t][k] = other,
                        None => {
                            return refuse(
                                "triangles",
                                format!(
                                "the mesh is not closed: the edge from vertex {a} to {b} borders triangles[{t}] only"
                            ),
                            )
                        }
                    }
                }
            }
            volume = tris
                .iter()
                .map(|t| points[t[0] as usize].dot(&points[t[1] as usize].cross(&points[t[2] as usize])))
                .sum::<f64>()
                / 6.0;
            if volume <= 0.0 {
                return refuse(
                    "triangles",
                    format!(
                        "the triangles face inward (the enclosed volume is {volume:e} m³): list each triangle's \
                         vertices counter-clockwise seen from outside"
                    ),
                );
            }
        } else {
            let mut edges: HashMap<(u32, u32), Vec<(u32, usize)>> = HashMap::with_capacity(3 * tris.len());
            for (t, tri) in tris.iter().enumerate() {
                for k in 0..3 {
                    let (a, b) = (tri[k], tri[(k + 1) % 3]);
                    edges.entry((a.min(b), a.max(b))).or_default().push((t as u32, k));
                }
            }
            for sharing in edges.values().filter(|s| s.len() == 2) {
                let ((t0, k0), (t1, k1)) = (sharing[0], sharing[1]);
                neighbours[t0 as usize][k0] = t1;
                neighbours[t1 as usize][k1] = t0;
            }
        }
        let area = tris
            .iter()
            .map(|t| {
                0.5 * (points[t[1] as usize] - points[t[0] as usize])
                    .cross(&(points[t[2] as usize] - points[t[0] as usize]))
                    .norm()
            })
            .sum();
        let edge_normals = (0..tris.len())
            .map(|t| std::array::from_fn(|k| (normals[t] + normals[neighbours[t][k] as usize]).normalize()))
            .collect();
        let mut vertex_normals = vec![V::zeros(); points.len()];
        for (t, tri) in tris.iter().enumerate() {
            for k in 0..3 {
                let p = points[tri[k] as usize];
                let (u, w) = (points[tri[(k + 1) % 3] as usize] - p, points[tri[(k + 2) % 3] as usize] - p);
                vertex_normals[tri[k] as usize] += normals[t] * u.angle(&w);
            }
        }
        for n in &mut vertex_normals {
            *n = n.normalize();
        }
        let tree = TriMesh::new(points.iter().map(|p| Point3::from(*p)).collect(), tris.clone())
            .map_err(|e| MeshError { key: "triangles", reason: e.to_string() })?;
        Ok(Self {
            vertices: points,
            triangles: tris,
            normals,
            edge_normals,
            vertex_normals,
            neighbours,
            crease_cos: crease_angle.cos(),
            tree,
            volume,
            area,
            size,
            lo,
            hi,
        })
    }

    /// Its vertices (m) and triangles (counter-clockwise seen from outside).
    pub fn triangles(&self) -> (&[V], &[[u32; 3]]) {
        (&self.vertices, &self.triangles)
    }

    /// Enclosed volume (m³).
    pub fn volume(&self) -> f64 {
        self.volume
    }

    /// Surface area (m²).
    pub fn area(&self) -> f64 {
        self.area
    }

    /// The lowest and the highest corner (m) of the bounding box.
    pub fn bounds(&self) -> (V, V) {
        (self.lo, self.hi)
    }

    /// Distance (m) from `x` to the bounding box (0 inside it): a lower bound of the distance to the
    /// surface from outside the box, for free.
    pub fn bounds_distance(&self, x: &V) -> f64 {
        (self.lo - x).sup(&(x - self.hi)).sup(&V::zeros()).norm()
    }

    pub fn num_triangles(&self) -> usize {
        self.triangles.len()
    }

    fn corners(&self, t: usize) -> [&V; 3] {
        self.triangles[t].map(|i| &self.vertices[i as usize])
    }

    /// The feature of a triangle that parry's projection landed on (its edge `k` runs from vertex `k` to
    /// `k + 1`; parry's edges are AB, BC, AC, the same three).
    fn feature(location: &TrianglePointLocation) -> Feature {
        match location {
            TrianglePointLocation::OnVertex(k) => Feature::Vertex(*k as usize),
            TrianglePointLocation::OnEdge(k, _) => Feature::Edge(*k as usize),
            _ => Feature::Face,
        }
    }

    /// The nearest point of the surface to `x`, the triangle it lies on and where on it.
    fn nearest(&self, x: &V) -> (V, usize, TrianglePointLocation) {
        let (proj, (t, location)) = self.tree.project_local_point_and_get_location(&Point3::from(*x), false);
        (proj.point.coords, t as usize, location)
    }

    /// Signed distance (m) to the surface, positive outside, and the outward unit normal: the distance's
    /// gradient, or on the surface the pseudo-normal there.
    pub fn signed_distance(&self, x: &V) -> (f64, V) {
        let (q, t, location) = self.nearest(x);
        self.signed_from(x, &q, t, &location)
    }

    /// The signed distance and outward normal at `x` from its nearest surface point `q`, on triangle `t` at
    /// `location`.
    fn signed_from(&self, x: &V, q: &V, t: usize, location: &TrianglePointLocation) -> (f64, V) {
        let pseudo = match Self::feature(location) {
            Feature::Vertex(k) => self.vertex_normals[self.triangles[t][k] as usize],
            Feature::Edge(k) => self.edge_normals[t][k],
            Feature::Face => self.normals[t],
        };
        let r = x - q;
        let d = r.norm();
        let sign = if r.dot(&pseudo) >= 0.0 { 1.0 } else { -1.0 };
        if d > 1e-12 * self.size {
            (sign * d, r * (sign / d))
        } else {
            (sign * d, pseudo)
        }
    }

    /// The feet of `x` on the surface within `reach` (m): the nearest point, and the perpendiculars that
    /// land on a face facing `x` (inside it, or on a seam); of feet whose normals differ by less than the crease angle (one
    /// direction) only the nearest. `into` is +1 where the wall lies outside the mesh (a container),
    /// −1 where it lies inside (an obstacle); `add` gets each foot and its normal into the wall. One pass
    /// over the triangles whose boxes lie within `reach` finds both.
    pub fn feet(&self, x: &V, reach: f64, into: f64, add: impl FnMut(V, V)) {
        if self.bounds_distance(x) >= reach {
            return;
        }
        let mut found = Feet::default();
        let tolerance = f64::EPSILON.sqrt() * reach;
        let point = Point3::from(*x);
        let aabb = Aabb::new(Point3::from(x - V::repeat(reach)), Point3::from(x + V::repeat(reach)));
        let mut nearest: Option<(f64, V, usize, TrianglePointLocation)> = None;
        for t in self.tree.bvh().intersect_aabb(&aabb) {
            let (projection, location) = self.tree.triangle(t).project_local_point_and_get_location(&point, false);
            let (q, t) = (projection.point.coords, t as usize);
            let distance = (x - q).norm();
            if distance >= reach {
                continue;
            }
            // Facing: the face lies ahead of x along its normal into the wall; its perpendicular lands on it
            // (inside, or on an edge shared with a face in the same plane, a seam).
            let normal = self.normals[t] * into;
            let perpendicular = matches!(location, TrianglePointLocation::OnFace(..))
                || (x - q).cross(&self.normals[t]).norm() <= 1e-9 * distance;
            if perpendicular && (q - x).dot(&normal) >= -tolerance {
                found.offer(q, normal, distance);
            }
            if nearest.as_ref().is_none_or(|(best, ..)| distance < *best) {
                nearest = Some((distance, q, t, location));
            }
        }
        if let Some((distance, q, t, location)) = nearest {
            let (_, n) = self.signed_from(x, &q, t, &location);
            found.offer(q, n * into, distance);
        }
        found.keep_distinct(self.crease_cos, add);
    }

    /// How many candidate points [`TriangleMesh::sample`] (or, with `half` (m), the thin wall's
    /// [`TriangleMesh::shell_sample`]) tries at `spacing` (m): what its memory and time scale with.
    pub fn sample_candidates(&self, spacing: f64, half: Option<f64>) -> f64 {
        let fine = spacing / 4.0;
        (0..self.triangles.len())
            .map(|t| {
                let [a, b, c] = self.corners(t);
                match half {
                    None => {
                        let longest = [(b - a).norm(), (c - b).norm(), (a - c).norm()].into_iter().fold(0.0, f64::max);
                        let m = (longest / fine).ceil() + 1.0;
                        0.5 * m * (m + 1.0)
                    }
                    Some(half) => {
                        let extent = a.sup(b).sup(c) - a.inf(b).inf(c) + V::repeat(2.0 * (half + 2.0 * fine));
                        (extent / fine).map(|e| e + 1.0).product()
                    }
                }
            })
            .sum()
    }

    /// Points on the surface at most `spacing` (m) apart with their outward normals (up to three, as
    /// [`crate::wall::Normals`]: repeated where fewer faces meet), by Poisson-disk elimination (see the
    /// module's documentation).
    pub fn sample(&self, spacing: f64) -> Vec<(V, [V; 3])> {
        let fine = spacing / 4.0;
        let radius = spacing - fine;
        let crease =
            |t: usize, k: usize| self.normals[t].dot(&self.normals[self.neighbours[t][k] as usize]) < self.crease_cos;
        // Distinct normals of the faces around each vertex on a crease.
        let mut around: Vec<Vec<V>> = vec![Vec::new(); self.vertices.len()];
        for (t, tri) in self.triangles.iter().enumerate() {
            for k in 0..3 {
                let n = self.normals[t];
                let list = &mut around[tri[k] as usize];
                if list.iter().all(|m| m.dot(&n) < self.crease_cos) {
                    list.push(n);
                }
            }
        }
        let mut on_crease = vec![false; self.vertices.len()];
        for (t, tri) in self.triangles.iter().enumerate() {
            for k in 0..3 {
                if crease(t, k) {
                    on_crease[tri[k] as usize] = true;
                    on_crease[tri[(k + 1) % 3] as usize] = true;
                }
            }
        }
        let mut corners = Vec::new();
        let mut creases = Vec::new();
        for (v, list) in around.iter().enumerate() {
            if !on_crease[v] || list.len() < 2 {
                continue;
            }
            let x = self.vertices[v];
            if list.len() == 2 {
                creases.push((x, [list[0], list[1], list[1]]));
            } else {
                // The three that span the most: the first, the one farthest from it, the one farthest
                // from both.
                let a = list[0];
                let b = *list.iter().min_by(|p, q| a.dot(p).total_cmp(&a.dot(q))).expect("three");
                let c = *list
                    .iter()
                    .max_by(|p, q| a.cross(&b).dot(p).abs().total_cmp(&a.cross(&b).dot(q).abs()))
                    .expect("three");
                corners.push((x, [a, b, c]));
            }
        }
        for (t, tri) in self.triangles.iter().enumerate() {
            for k in 0..3 {
                // Each crease edge once: from the triangle that runs it from the lower index.
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                if a < b && crease(t, k) {
                    let (pa, pb) = (self.vertices[a as usize], self.vertices[b as usize]);
                    let other = self.normals[self.neighbours[t][k] as usize];
                    let parts = ((pb - pa).norm() / fine).ceil().max(1.0) as usize;
                    for i in 1..parts {
                        creases.push((pa + (pb - pa) * (i as f64 / parts as f64), [self.normals[t], other, other]));
                    }
                }
            }
        }
        let mut faces = Vec::new();
        for (t, normal) in self.normals.iter().enumerate() {
            let [a, b, c] = self.corners(t);
            let longest = [(b - a).norm(), (c - b).norm(), (a - c).norm()].into_iter().fold(0.0, f64::max);
            let parts = (longest / fine).ceil().max(1.0) as usize;
            for i in 0..=parts {
                for j in 0..=parts - i {
                    let x = a + (b - a) * (i as f64 / parts as f64) + (c - a) * (j as f64 / parts as f64);
                    faces.push((x, [*normal; 3]));
                }
            }
        }
        eliminate(corners.into_iter().chain(creases).chain(faces), radius)
    }
}

/// A thin wall: the points within `half` (m) of a mesh's triangles (open or closed, any orientation).
impl TriangleMesh {
    /// Signed distance (m) to the surface of the thin wall around the mesh, positive outside it, and its
    /// outward normal: away from the nearest point of the middle surface (its face's normal there, on it).
    pub fn shell_distance(&self, x: &V, half: f64) -> (f64, V) {
        let (q, t, _) = self.nearest(x);
        let r = x - q;
        let d = r.norm();
        let n = if d > 1e-12 * self.size { r / d } else { self.normals[t] };
        (d - half, n)
    }

    /// The feet of `x` on the thin wall's surface within `reach` (m), with normals into the wall: the
    /// nearest point, and the perpendiculars to the faces within reach whose foot lands inside them,
    /// offset by `half` towards `x`; of feet whose normals differ by less than the crease angle of a closed
    /// mesh (here 30°) only the nearest.
    pub fn shell_feet(&self, x: &V, reach: f64, half: f64, add: impl FnMut(V, V)) {
        if self.bounds_distance(x) >= reach + half {
            return;
        }
        let mut found = Feet::default();
        let point = Point3::from(*x);
        let around = reach + half;
        let aabb = Aabb::new(Point3::from(x - V::repeat(around)), Point3::from(x + V::repeat(around)));
        let mut nearest: Option<(f64, V, usize)> = None;
        for t in self.tree.bvh().intersect_aabb(&aabb) {
            let (projection, location) = self.tree.triangle(t).project_local_point_and_get_location(&point, false);
            let (q, t) = (projection.point.coords, t as usize);
            let distance = (x - q).norm();
            if distance - half >= reach {
                continue;
            }
            if nearest.is_none_or(|(best, ..)| distance < best) {
                nearest = Some((distance, q, t));
            }
            if matches!(location, TrianglePointLocation::OnFace(..)) && distance > 0.0 {
                let side = if (x - q).dot(&self.normals[t]) >= 0.0 { 1.0 } else { -1.0 };
                let out = self.normals[t] * side;
                found.offer(q + out * half, -out, (distance - half).abs());
            }
        }
        if let Some((distance, q, t)) = nearest {
            let out = if distance > 1e-12 * self.size { (x - q) / distance } else { self.normals[t] };
            found.offer(q + out * half, -out, (distance - half).abs());
        }
        found.keep_distinct((std::f64::consts::PI / 6.0).cos(), add);
    }

    /// Points on the thin wall's surface at most `spacing` (m) apart, with their outward normals: the points
    /// of a lattice `spacing/4` fine near each triangle (within `half` and two lattice steps of it), each
    /// moved along the way from its nearest middle-surface point to `half` from it, kept where no other face
    /// is nearer (on the surface, not inside the wall), then thinned by Poisson-disk elimination at 0.7
    /// spacing; the sheets on either side, the rims along open edges and the round caps at corners are
    /// sampled alike.
    pub fn shell_sample(&self, spacing: f64, half: f64) -> Vec<(V, V)> {
        let fine = spacing / 4.0;
        let margin = V::repeat(half + 2.0 * fine);
        let mut seen = std::collections::HashSet::new();
        let mut candidates = Vec::new();
        for t in 0..self.triangles.len() {
            let [a, b, c] = self.corners(t);
            let lo = ((a.inf(b).inf(c) - margin) / fine).map(|v| v.floor() as i64);
            let hi = ((a.sup(b).sup(c) + margin) / fine).map(|v| v.ceil() as i64);
            for i in lo.x..=hi.x {
                for j in lo.y..=hi.y {
                    for k in lo.z..=hi.z {
                        if !seen.insert((i, j, k)) {
                            continue;
                        }
                        let p = V::new(i as f64, j as f64, k as f64) * fine;
                        let (q, t, _) = self.nearest(&p);
                        let d = (p - q).norm();
                        if (d - half).abs() > fine {
                            continue;
                        }
                        let out = if d > 1e-12 * self.size { (p - q) / d } else { self.normals[t] };
                        let on = q + out * half;
                        if (self.nearest(&on).0 - on).norm() >= half * (1.0 - 1e-9) {
                            candidates.push((on, out));
                        }
                    }
                }
            }
        }
        eliminate(candidates, 0.7 * spacing)
    }
}

/// Poisson-disk elimination: the candidates in order, each kept unless a kept one lies within `radius`
/// (m) of it (looked up on a hash grid of cells `radius` wide).
fn eliminate<T>(candidates: impl IntoIterator<Item = (V, T)>, radius: f64) -> Vec<(V, T)> {
    let cell = |x: &V| (x / radius).map(|c| c.floor() as i64);
    let mut grid: HashMap<(i64, i64, i64), Vec<usize>> = HashMap::new();
    let mut kept: Vec<(V, T)> = Vec::new();
    for (x, data) in candidates {
        let c = cell(&x);
        let near =
            (-1..=1).flat_map(|i| (-1..=1).flat_map(move |j| (-1..=1).map(move |k| (c.x + i, c.y + j, c.z + k))));
        let taken = near
            .into_iter()
            .any(|key| grid.get(&key).is_some_and(|list| list.iter().any(|&p| (kept[p].0 - x).norm() < radius)));
        if !taken {
            grid.entry((c.x, c.y, c.z)).or_default().push(kept.len());
            kept.push((x, data));
        }
    }
    kept
}

/// Builders of simple closed meshes, for tests and examples.
pub mod shapes {
    /// An axis-aligned box from `lo` to `hi` (m): 8 vertices, 12 triangles facing out.
    pub fn cuboid(lo: [f64; 3], hi: [f64; 3]) -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
        let v = (0..8).map(|c| std::array::from_fn(|k| if c >> k & 1 == 0 { lo[k] } else { hi[k] })).collect();
        // Faces as quads (counter-clockwise from outside), split in two.
        let quads = [[0, 4, 6, 2], [1, 3, 7, 5], [0, 1, 5, 4], [2, 6, 7, 3], [0, 2, 3, 1], [4, 5, 7, 6]];
        let t = quads.iter().flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]).collect();
        (v, t)
    }

    /// A sphere of `radius` (m) about `centre`: an icosahedron subdivided `levels` times, its vertices
    /// pushed onto the sphere.
    pub fn icosphere(centre: [f64; 3], radius: f64, levels: usize) -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
        let g = (1.0 + 5f64.sqrt()) / 2.0;
        let mut v: Vec<[f64; 3]> = vec![
            [-1.0, g, 0.0],
            [1.0, g, 0.0],
            [-1.0, -g, 0.0],
            [1.0, -g, 0.0],
            [0.0, -1.0, g],
            [0.0, 1.0, g],
            [0.0, -1.0, -g],
            [0.0, 1.0, -g],
            [g, 0.0, -1.0],
            [g, 0.0, 1.0],
            [-g, 0.0, -1.0],
            [-g, 0.0, 1.0],
        ];
        let mut t: Vec<[usize; 3]> = vec![
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ];
        for _ in 0..levels {
            let mut mid = std::collections::HashMap::new();
            let mut middle = |a: usize, b: usize, v: &mut Vec<[f64; 3]>| {
                *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    v.push(std::array::from_fn(|k| 0.5 * (v[a][k] + v[b][k])));
                    v.len() - 1
                })
            };
            let mut next = Vec::with_capacity(4 * t.len());
            for [a, b, c] in t {
                let (ab, bc, ca) = (middle(a, b, &mut v), middle(b, c, &mut v), middle(c, a, &mut v));
                next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
            }
            t = next;
        }
        let v = v
            .iter()
            .map(|p| {
                let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
                std::array::from_fn(|k| centre[k] + radius * p[k] / n)
            })
            .collect();
        (v, t)
    }
}

#[cfg(test)]
mod tests {
    use super::shapes::{cuboid, icosphere};
    use super::*;

    /// The least distance (m) between two of the sampled `points`.
    fn closest_pair<T>(points: &[(V, T)]) -> f64 {
        let mut closest = f64::INFINITY;
        for (i, (x, _)) in points.iter().enumerate() {
            for (y, _) in &points[i + 1..] {
                closest = closest.min((y - x).norm());
            }
        }
        closest
    }

    fn uniform(n: usize) -> Vec<f64> {
        let mut s = 0x9e3779b97f4a7c15u64;
        (0..n)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                (s >> 11) as f64 / (1u64 << 53) as f64
            })
            .collect()
    }

    /// A turned box as a mesh: the distance to its surface equals that of the exact box (to 1e-12 m),
    /// with the sign right inside, outside, near edges and corners.
    #[test]
    fn signed_distance_of_a_box_mesh_is_exact() {
        let (v, t) = cuboid([0.2, 0.3, 0.25], [0.7, 0.6, 0.8]);
        let mesh = TriangleMesh::new(&v, &t, 0.5).expect("a closed box");
        assert!((mesh.volume() - 0.5 * 0.3 * 0.55).abs() < 1e-12);
        let r = uniform(3 * 2000);
        for k in 0..2000 {
            let x = V::new(r[3 * k], r[3 * k + 1], r[3 * k + 2]);
            let q = (x - V::new(0.45, 0.45, 0.525)).abs() - V::new(0.25, 0.15, 0.275);
            let exact = q.map(|c| c.max(0.0)).norm() + q.max().min(0.0);
            let (d, n) = mesh.signed_distance(&x);
            assert!((d - exact).abs() < 1e-12, "{x}: {d} vs {exact}");
            assert!((n.norm() - 1.0).abs() < 1e-12);
        }
    }

    /// Refused, naming why: an open mesh, one with a triangle turned over, one facing inward, an index out
    /// of range; an STL-like mesh (every triangle with its own copies of the vertices) is welded and taken.
    #[test]
    fn bad_meshes_are_refused() {
        let (v, t) = cuboid([0.0; 3], [1.0; 3]);
        let open = TriangleMesh::new(&v, &t[..11], 0.5).unwrap_err();
        assert!(open.reason.contains("not closed"), "{open:?}");
        let mut flipped = t.clone();
        flipped[3].swap(1, 2);
        assert!(TriangleMesh::new(&v, &flipped, 0.5).unwrap_err().reason.contains("consistently oriented"));
        let inward: Vec<_> = t.iter().map(|&[a, b, c]| [a, c, b]).collect();
        assert!(TriangleMesh::new(&v, &inward, 0.5).unwrap_err().reason.contains("face inward"));
        let mut far = t.clone();
        far[0][0] = 8;
        assert_eq!(TriangleMesh::new(&v, &far, 0.5).unwrap_err().key, "triangles");
        let soup: Vec<[f64; 3]> = t.iter().flat_map(|tri| tri.map(|i| v[i])).collect();
        let soup_t: Vec<[usize; 3]> = (0..t.len()).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect();
        assert!((TriangleMesh::new(&soup, &soup_t, 0.5).expect("welded").volume() - 1.0).abs() < 1e-12);
    }

    /// Boundary points of a box mesh and a sphere mesh: on the surface, every surface point within
    /// `spacing` of one, no two closer than 3/4 spacing; the box's 8 corners carry three normals and its
    /// edges two, and its faces (split into two triangles each) one.
    #[test]
    fn samples_cover_the_surface_at_spacing() {
        let spacing = 0.05;
        for (v, t) in [cuboid([0.2, 0.3, 0.25], [0.7, 0.6, 0.8]), icosphere([0.5, 0.5, 0.5], 0.3, 3)] {
            let mesh = TriangleMesh::new(&v, &t, 0.5).expect("closed");
            let points = mesh.sample(spacing);
            for (x, _) in &points {
                assert!(mesh.signed_distance(x).0.abs() < 1e-12);
            }
            let closest = closest_pair(&points);
            assert!(closest >= 0.75 * spacing - 1e-12, "two points {closest} apart");
            let r = uniform(3 * 3000);
            for k in 0..3000 {
                let x = V::new(r[3 * k], r[3 * k + 1], r[3 * k + 2]);
                let (d, n) = mesh.signed_distance(&x);
                let on = x - n * d;
                let nearest = points.iter().map(|p| (p.0 - on).norm()).fold(f64::INFINITY, f64::min);
                assert!(nearest <= spacing, "{on} is {} spacings from a point", nearest / spacing);
            }
            if t.len() == 12 {
                let count = |m: usize| {
                    points.iter().filter(|(_, n)| (n[0] != n[1]) as usize + (n[1] != n[2]) as usize + 1 == m).count()
                };
                assert_eq!(count(3), 8);
                assert!(count(2) >= 12 * 3, "edges sampled with two normals");
                assert!(points.iter().all(|(x, n)| n.iter().all(|m| (m.norm() - 1.0).abs() < 1e-12) && x.z > 0.0));
            } else {
                assert!(points.iter().all(|(_, n)| n[0] == n[1] && n[1] == n[2]), "a sphere has no crease");
            }
        }
    }

    /// Feet: a particle near a corner inside a box mesh has one foot on each of the three faces (each
    /// face split into two triangles counts once); near a finely triangulated sphere, one (the nearest).
    #[test]
    fn feet_on_faces_not_on_triangles() {
        let (v, t) = cuboid([0.0; 3], [1.0; 3]);
        let mesh = TriangleMesh::new(&v, &t, 0.5).expect("closed");
        let mut feet = Vec::new();
        mesh.feet(&V::new(0.97, 0.98, 0.96), 0.1, 1.0, |q, n| feet.push((q, n)));
        assert_eq!(feet.len(), 3, "{feet:?}");
        for (q, n) in &feet {
            assert!((q - V::new(0.97, 0.98, 0.96)).dot(n) > 0.0 && (n.norm() - 1.0).abs() < 1e-12);
        }
        let (v, t) = icosphere([0.5; 3], 0.3, 4);
        let sphere = TriangleMesh::new(&v, &t, 0.5).expect("closed");
        let mut feet = Vec::new();
        sphere.feet(&V::new(0.5, 0.5, 0.82), 0.1, -1.0, |q, n| feet.push((q, n)));
        assert_eq!(feet.len(), 1);
        assert!((feet[0].1 + V::z()).norm() < 0.1, "into the obstacle: {:?}", feet[0].1);
    }

    /// A thin wall around an open square plate turned in no coordinate plane: its distance is the distance
    /// to the plate less the half thickness; its samples lie on its surface (both sheets, rims and corners),
    /// cover it at the spacing and are at least 0.7 spacing apart; the feet of a point above the plate's
    /// middle are one, on the upper sheet, facing down into the wall.
    #[test]
    fn a_thin_wall_around_an_open_plate() {
        let r = nalgebra::Rotation3::from_euler_angles(0.3, -0.5, 0.2);
        let centre = V::new(0.5, 0.5, 0.5);
        let corner = |u: f64, v: f64| -> [f64; 3] { (centre + r * V::new(u, 0.0, v)).into() };
        let v = vec![corner(-0.2, -0.2), corner(0.2, -0.2), corner(0.2, 0.2), corner(-0.2, 0.2)];
        let plate = TriangleMesh::open(&v, &[[0, 1, 2], [0, 2, 3]]).expect("an open plate");
        let half = 0.03;
        let exact = |x: &V| {
            let l = r.inverse() * (x - centre);
            let (du, dv) = ((l.x.abs() - 0.2).max(0.0), (l.z.abs() - 0.2).max(0.0));
            (du * du + l.y * l.y + dv * dv).sqrt() - half
        };
        let rnd = uniform(3 * 2000);
        for k in 0..2000 {
            let x = V::new(rnd[3 * k], rnd[3 * k + 1], rnd[3 * k + 2]);
            assert!((plate.shell_distance(&x, half).0 - exact(&x)).abs() < 1e-12);
        }
        let spacing = 0.02;
        let points = plate.shell_sample(spacing, half);
        for (x, n) in &points {
            assert!(exact(x).abs() < 1e-12 && (n.norm() - 1.0).abs() < 1e-12);
        }
        let closest = closest_pair(&points);
        assert!(closest >= 0.7 * spacing - 1e-12, "two points {closest} apart");
        for k in 0..2000 {
            let x = V::new(rnd[3 * k], rnd[3 * k + 1], rnd[3 * k + 2]);
            let (d, n) = plate.shell_distance(&x, half);
            let on = x - n * d;
            let nearest = points.iter().map(|p| (p.0 - on).norm()).fold(f64::INFINITY, f64::min);
            assert!(nearest <= spacing, "{on} is {} spacings from a point", nearest / spacing);
        }
        let above = centre + r * V::new(0.05, 0.04, -0.03);
        let mut feet = Vec::new();
        plate.shell_feet(&above, 0.05, half, |q, n| feet.push((q, n)));
        assert_eq!(feet.len(), 1);
        assert!((feet[0].0 - (centre + r * V::new(0.05, half, -0.03))).norm() < 1e-12);
        assert!((feet[0].1 + r * V::y()).norm() < 1e-12);
    }
}
