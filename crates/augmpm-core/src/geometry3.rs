//! The walls of a 3D scene: half-spaces, oriented boxes, spheres and capped cylinders, each a container
//! (material inside) or an obstacle (material outside), and [`Walls3`], the material region they bound
//! with the domain box. Normals point from the material into the wall, as in 2D ([`crate::geometry`]).
//!
//! Boundary points are sampled on the surfaces at most `spacing` apart, uniformly whatever the surface's
//! orientation: a square lattice on each plane and box face (its edges and corners sampled once, with
//! two and three normals), latitude rings on spheres, rings along cylinders and on their caps, and
//! Poisson-disk samples on triangle meshes ([`crate::mesh`]).

use crate::geometry::{Placement, Region, Side, WallDistance, WallFeet, WallFoot};
use crate::math::{Matrix, Real, Vector};
use crate::mesh::TriangleMesh;
use crate::motion::{Motion3, Pose3, WallPose};
use crate::wall::BoundaryPoint;
use std::sync::Arc;

type P3 = Vector<3>;

/// A solid, whose surface is a wall.
#[derive(Clone, Debug, PartialEq)]
pub enum Solid {
    /// The half-space `n·(x − point) ≤ 0`; `normal` (unit) points out of it.
    HalfSpace {
        point: P3,
        normal: P3,
    },
    /// A box: `centre`, half extents along its axes, and its axes (orthonormal columns of `axes`).
    Box {
        centre: P3,
        half: P3,
        axes: Matrix<3>,
    },
    Sphere {
        centre: P3,
        radius: Real,
    },
    /// A capped cylinder: `centre` of its axis, unit `axis`, `radius`, and half its length.
    Cylinder {
        centre: P3,
        axis: P3,
        radius: Real,
        half_length: Real,
    },
    /// A closed triangle mesh, placed (held in f64 in either precision).
    Mesh(Arc<TriangleMesh>),
    /// A thin wall: the points within `half` (m) of a mesh's triangles (open or closed).
    Shell {
        mesh: Arc<TriangleMesh>,
        half: Real,
    },
}

/// A vector in the mesh's double precision, and back.
fn wide(v: &P3) -> nalgebra::Vector3<f64> {
    v.map(crate::math::wide)
}

fn narrow(v: &nalgebra::Vector3<f64>) -> P3 {
    v.map(|c| c as Real)
}

/// A wall: a solid with the material inside it (a container; a half-space always) or outside it (an
/// obstacle).
#[derive(Clone, Debug, PartialEq)]
pub struct Wall3 {
    pub solid: Solid,
    pub side: Side,
}

/// A unit vector orthogonal to `n` (unit), and a third completing the right-handed basis.
fn tangents(n: &P3) -> (P3, P3) {
    let helper = if n.x.abs() < 0.9 { P3::new(1.0, 0.0, 0.0) } else { P3::new(0.0, 1.0, 0.0) };
    let t1 = n.cross(&helper).normalize();
    (t1, n.cross(&t1))
}

impl Solid {
    /// The solid's centre (m): a half-space's point, a mesh's bounding box's centre.
    pub fn centre(&self) -> P3 {
        match self {
            Solid::HalfSpace { point, .. } => *point,
            Solid::Box { centre, .. } | Solid::Sphere { centre, .. } | Solid::Cylinder { centre, .. } => *centre,
            Solid::Mesh(mesh) | Solid::Shell { mesh, .. } => {
                let (lo, hi) = mesh.bounds();
                narrow(&((lo + hi) * 0.5))
            }
        }
    }

    /// A bound on the distance (m) of the solid's surface points from `p` (infinite for a half-space).
    pub fn reach_from(&self, p: &P3) -> Real {
        let away = (self.centre() - p).norm();
        match self {
            Solid::HalfSpace { .. } => Real::INFINITY,
            Solid::Box { half, .. } => away + half.norm(),
            Solid::Sphere { radius, .. } => away + radius,
            Solid::Cylinder { radius, half_length, .. } => away + radius.hypot(*half_length),
            Solid::Mesh(mesh) => {
                let (lo, hi) = mesh.bounds();
                away + ((hi - lo) * 0.5).norm() as Real
            }
            Solid::Shell { mesh, half } => {
                let (lo, hi) = mesh.bounds();
                away + ((hi - lo) * 0.5).norm() as Real + half
            }
        }
    }

    /// Signed distance (m) to the surface, positive outside the solid, and the outward unit normal of
    /// the nearest surface point.
    pub fn signed_distance(&self, x: &P3) -> (Real, P3) {
        match self {
            Solid::HalfSpace { point, normal } => (normal.dot(&(x - point)), *normal),
            Solid::Box { centre, half, axes } => {
                let q = axes.transpose() * (x - centre);
                let d = q.abs() - half;
                let out = d.map(|c| c.max(0.0));
                let outside = out.norm();
                if outside > 0.0 {
                    let local = P3::from_fn(|k, _| out[k] * q[k].signum()) / outside;
                    (outside, axes * local)
                } else {
                    let k = d.imax();
                    let mut local = P3::zeros();
                    local[k] = if q[k] < 0.0 { -1.0 } else { 1.0 };
                    (d[k], axes * local)
                }
            }
            Solid::Sphere { centre, radius } => {
                let r = x - centre;
                let n = r.norm();
                (n - radius, if n > 1e-300 { r / n } else { P3::new(0.0, 1.0, 0.0) })
            }
            Solid::Cylinder { centre, axis, radius, half_length } => {
                let rel = x - centre;
                let a = axis.dot(&rel);
                let radial = rel - axis * a;
                let r = radial.norm();
                let out_dir = if r > 1e-300 { radial / r } else { tangents(axis).0 };
                let along = if a < 0.0 { -axis } else { *axis };
                let (d0, d1) = (r - radius, a.abs() - half_length);
                let (o0, o1) = (d0.max(0.0), d1.max(0.0));
                let outside = o0.hypot(o1);
                if outside > 0.0 {
                    (outside, (out_dir * o0 + along * o1) / outside)
                } else if d0 > d1 {
                    (d0, out_dir)
                } else {
                    (d1, along)
                }
            }
            Solid::Mesh(mesh) => {
                let (d, n) = mesh.signed_distance(&wide(x));
                (d as Real, narrow(&n))
            }
            Solid::Shell { mesh, half } => {
                let (d, n) = mesh.shell_distance(&wide(x), crate::math::wide(*half));
                (d as Real, narrow(&n))
            }
        }
    }

    /// Points on the surface at most `spacing` (m) apart with their outward normals (up to three, as
    /// [`crate::wall::Normals`]: repeated where fewer faces meet). A half-space is sampled where it
    /// crosses the box `[lo, hi]`.
    pub fn surface(&self, spacing: Real, lo: &P3, hi: &P3) -> Vec<(P3, [P3; 3])> {
        let mut out = Vec::new();
        let parts = |length: Real| (length / spacing).ceil().max(1.0) as usize;
        let at = |from: Real, to: Real, n: usize, i: usize| from + (to - from) * i as Real / n as Real;
        match self {
            Solid::HalfSpace { point, normal } => {
                let (t1, t2) = tangents(normal);
                // The lattice's extent: the box's corners seen along the plane.
                let (mut a, mut b) = ([Real::INFINITY; 2], [Real::NEG_INFINITY; 2]);
                for k in 0..8 {
                    let corner = P3::new(
                        if k & 1 == 0 { lo.x } else { hi.x },
                        if k & 2 == 0 { lo.y } else { hi.y },
                        if k & 4 == 0 { lo.z } else { hi.z },
                    );
                    for (j, t) in [t1, t2].iter().enumerate() {
                        let c = t.dot(&(corner - point));
                        a[j] = a[j].min(c);
                        b[j] = b[j].max(c);
                    }
                }
                let (n1, n2) = (
                    (((b[0] - a[0]) / spacing).floor() as usize) + 1,
                    (((b[1] - a[1]) / spacing).floor() as usize) + 1,
                );
                for i in 0..=n1 {
                    for j in 0..=n2 {
                        let x = point + t1 * (a[0] + spacing * i as Real) + t2 * (a[1] + spacing * j as Real);
                        if (0..3).all(|k| x[k] >= lo[k] - spacing && x[k] <= hi[k] + spacing) {
                            out.push((x, [*normal; 3]));
                        }
                    }
                }
            }
            Solid::Box { centre, half, axes } => {
                let n: [usize; 3] = std::array::from_fn(|k| parts(2.0 * half[k]));
                let axis = |k: usize, sign: Real| axes.column(k) * sign;
                let place = |q: P3| centre + axes * q;
                // Faces: interior lattice points, one normal.
                for k in 0..3 {
                    let (j, l) = ((k + 1) % 3, (k + 2) % 3);
                    for sign in [-1.0, 1.0] {
                        for i in 1..n[j] {
                            for m in 1..n[l] {
                                let mut q = P3::zeros();
                                q[k] = sign * half[k];
                                q[j] = at(-half[j], half[j], n[j], i);
                                q[l] = at(-half[l], half[l], n[l], m);
                                out.push((place(q), [axis(k, sign); 3]));
                            }
                        }
                    }
                }
                // Edges along axis k: interior points, the two faces' normals.
                for k in 0..3 {
                    let (j, l) = ((k + 1) % 3, (k + 2) % 3);
                    for (sj, sl) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
                        for i in 1..n[k] {
                            let mut q = P3::zeros();
                            q[k] = at(-half[k], half[k], n[k], i);
                            q[j] = sj * half[j];
                            q[l] = sl * half[l];
                            let (a, b) = (axis(j, sj), axis(l, sl));
                            out.push((place(q), [a, b, b]));
                        }
                    }
                }
                // Corners: the three faces' normals.
                for c in 0..8 {
                    let s = P3::new(
                        if c & 1 == 0 { -1.0 } else { 1.0 },
                        if c & 2 == 0 { -1.0 } else { 1.0 },
                        if c & 4 == 0 { -1.0 } else { 1.0 },
                    );
                    out.push((place(half.component_mul(&s)), [axis(0, s.x), axis(1, s.y), axis(2, s.z)]));
                }
            }
            Solid::Sphere { centre, radius } => {
                let rings = parts(crate::math::PI * radius);
                for i in 0..=rings {
                    let theta = crate::math::PI * i as Real / rings as Real;
                    let (st, ct) = theta.sin_cos();
                    let count = if i == 0 || i == rings { 1 } else { parts(2.0 * crate::math::PI * radius * st) };
                    for m in 0..count {
                        let phi = 2.0 * crate::math::PI * m as Real / count as Real;
                        let n = P3::new(st * phi.cos(), ct, st * phi.sin());
                        out.push((centre + n * *radius, [n; 3]));
                    }
                }
            }
            Solid::Cylinder { centre, axis, radius, half_length } => {
                let (t1, t2) = tangents(axis);
                let around = parts(2.0 * crate::math::PI * radius);
                let radial = |phi: Real| t1 * phi.cos() + t2 * phi.sin();
                let steps = parts(2.0 * half_length);
                for i in 0..=steps {
                    let a = at(-*half_length, *half_length, steps, i);
                    for m in 0..around {
                        let r = radial(2.0 * crate::math::PI * m as Real / around as Real);
                        let x = centre + axis * a + r * *radius;
                        // The rims are edges: the side's and the cap's normals.
                        let cap = if i == 0 { -*axis } else { *axis };
                        out.push((x, if i == 0 || i == steps { [r, cap, cap] } else { [r; 3] }));
                    }
                }
                let rings = parts(*radius);
                for sign in [-1.0, 1.0] {
                    for j in 0..rings {
                        let rho = radius * j as Real / rings as Real;
                        let count = if j == 0 { 1 } else { parts(2.0 * crate::math::PI * rho) };
                        for m in 0..count {
                            let r = radial(2.0 * crate::math::PI * m as Real / count as Real);
                            out.push((centre + axis * (sign * half_length) + r * rho, [*axis * sign; 3]));
                        }
                    }
                }
            }
            Solid::Mesh(mesh) => {
                for (x, normals) in mesh.sample(crate::math::wide(spacing)) {
                    out.push((narrow(&x), normals.map(|n| narrow(&n))));
                }
            }
            Solid::Shell { mesh, half } => {
                for (x, n) in mesh.shell_sample(crate::math::wide(spacing), crate::math::wide(*half)) {
                    out.push((narrow(&x), [narrow(&n); 3]));
                }
            }
        }
        out
    }

    /// The feet of the perpendiculars from `x` on the surface's faces that they land inside of (each
    /// with the face's outward normal and its curvature around the solid's inside, 1/m), for a
    /// container's material inside.
    fn face_feet(&self, x: &P3, mut add: impl FnMut(P3, P3, Real)) {
        match self {
            Solid::HalfSpace { point, normal } => add(x - normal * normal.dot(&(x - point)), *normal, 0.0),
            Solid::Box { centre, half, axes } => {
                let q = axes.transpose() * (x - centre);
                for k in 0..3 {
                    let inside_face = (0..3).filter(|&j| j != k).all(|j| q[j].abs() <= half[j]);
                    if inside_face {
                        for sign in [-1.0, 1.0] {
                            let mut f = q;
                            f[k] = sign * half[k];
                            add(centre + axes * f, axes.column(k) * sign, 0.0);
                        }
                    }
                }
            }
            Solid::Sphere { centre, radius } => {
                let r = x - centre;
                let n = r.norm();
                if n > 0.0 {
                    add(centre + r / n * *radius, r / n, 1.0 / radius);
                }
            }
            Solid::Cylinder { centre, axis, radius, half_length } => {
                let rel = x - centre;
                let a = axis.dot(&rel);
                let radial = rel - axis * a;
                let r = radial.norm();
                if r > 0.0 && a.abs() <= *half_length {
                    // Curved one way only: no chord correction (that of `curvature` assumes a sphere).
                    add(centre + axis * a + radial / r * *radius, radial / r, 0.0);
                }
                if r <= *radius {
                    for sign in [-1.0, 1.0] {
                        add(centre + axis * (sign * half_length) + radial, *axis * sign, 0.0);
                    }
                }
            }
            // Their feet depend on the side the material is on: `Walls3::wall_feet`.
            Solid::Mesh(_) | Solid::Shell { .. } => {}
        }
    }
}

/// Surface points of the drawn walls by spacing (m), shared by clones of the same walls.
type SampleCache = std::sync::Arc<std::sync::Mutex<Vec<(Real, std::sync::Arc<Vec<BoundaryPoint<3>>>)>>>;

/// The material region of a 3D scene: inside the domain box and on the material side of every wall.
/// Wall `i < walls.len()` is a scene wall; index `walls.len()` is the domain box. A moving wall is its
/// drawn solid placed by its pose ([`Motion3`]): distances, feet and boundary points are taken in the
/// drawing's frame and placed.
#[derive(Clone, Debug)]
pub struct Walls3 {
    pub walls: Vec<Wall3>,
    domain: Solid,
    extent: P3,
    /// Each wall's motion, if it moves.
    moves: Vec<Option<Motion3>>,
    /// Poses set from outside (`Simulation::set_wall_pose`), which take over from `moves`.
    set: Vec<Option<WallPose<3>>>,
    /// Each wall's pose at the start and at the end of the step ([`Region::set_time`]).
    now: Vec<Pose3>,
    next: Vec<Pose3>,
    dt: Real,
    /// How far any wall point moved at the last [`Region::set_time`] (m).
    sweep: Real,
    /// The drawn walls' surface points at the spacings (m) asked for, each sampled once (the grid's, and
    /// that of the frames): moving walls' points are placed.
    drawn_points: SampleCache,
}

impl Walls3 {
    /// The walls of a domain box `[0, extent]`.
    pub fn new(walls: Vec<Wall3>, extent: P3) -> Self {
        let domain = Solid::Box { centre: extent * 0.5, half: extent * 0.5, axes: Matrix::<3>::identity() };
        let n = walls.len();
        let (now, next) = (vec![Pose3::still(P3::zeros()); n], vec![Pose3::still(P3::zeros()); n]);
        let (moves, set) = (vec![None; n], vec![None; n]);
        Self { walls, domain, extent, moves, set, now, next, dt: 0.0, sweep: 0.0, drawn_points: Default::default() }
    }

    /// The walls moving as `moves` says (one entry per wall), each about its motion's pivot or its
    /// centre; a half-space cannot move (an error names the wall).
    pub fn with_moves(mut self, moves: Vec<Option<Motion3>>) -> Result<Self, usize> {
        assert_eq!(moves.len(), self.walls.len(), "one motion (or none) per wall");
        if let Some(i) =
            (0..moves.len()).find(|&i| moves[i].is_some() && matches!(self.walls[i].solid, Solid::HalfSpace { .. }))
        {
            return Err(i);
        }
        for (i, motion) in moves.iter().enumerate() {
            if let Some(m) = motion {
                let pose = m.pose(0.0, self.walls[i].solid.centre());
                (self.now[i], self.next[i]) = (pose, pose);
            }
        }
        self.moves = moves;
        Ok(self)
    }

    /// Index of the domain box among the walls.
    pub fn box_index(&self) -> usize {
        self.walls.len()
    }

    /// The domain box's far corner (m); its near corner is the origin.
    pub fn extent(&self) -> P3 {
        self.extent
    }

    /// The farthest distance (m) of wall `wall`'s points from its pivot.
    fn reach(&self, wall: usize) -> Real {
        self.walls[wall].solid.reach_from(&self.now[wall].pivot)
    }

    /// The fastest moving wall and the largest speed (m/s) of any of its points, if a wall moves.
    pub fn fastest(&self) -> Option<(usize, Real)> {
        (0..self.walls.len())
            .filter_map(|i| self.moves[i].as_ref().map(|m| (i, m.top_speed(self.reach(i)))))
            .max_by(|a, b| a.1.total_cmp(&b.1))
    }

    /// Whether wall `wall` moves: by its scene's motion or posed from outside.
    fn driven(&self, wall: usize) -> bool {
        self.moves.get(wall).is_some_and(Option::is_some) || self.set.get(wall).is_some_and(Option::is_some)
    }

    /// The pose of moving wall `wall` now, or none for a still one.
    fn pose(&self, wall: usize) -> Option<&Pose3> {
        self.driven(wall).then(|| &self.now[wall])
    }

    /// The point wall `wall` turns about: its motion's pivot, else its centre as drawn.
    pub fn pivot(&self, wall: usize) -> P3 {
        let centre = self.walls[wall].solid.centre();
        self.moves[wall].as_ref().and_then(Motion3::pivot).map_or(centre, P3::from)
    }

    /// The signed distance of wall `wall`'s material side (positive in the wall) and its normal there.
    fn wall_distance(&self, wall: usize) -> impl Fn(&P3) -> (Real, P3) + '_ {
        move |x| {
            let (solid, side) = if wall == self.walls.len() {
                (&self.domain, Side::Inside)
            } else {
                (&self.walls[wall].solid, self.walls[wall].side)
            };
            let (d, n) = match self.pose(wall) {
                Some(pose) => {
                    let (d, n) = solid.signed_distance(&pose.unplace(x));
                    (d, pose.turn(&n))
                }
                None => solid.signed_distance(x),
            };
            match (solid, side) {
                (Solid::HalfSpace { .. }, _) | (_, Side::Inside) => (d, n),
                (_, Side::Outside) => (-d, -n),
            }
        }
    }

    /// Velocity (m/s) over the step of the point of wall `wall` at `x`: where its pose at the end of the
    /// step puts it, less where it is, over the step.
    fn velocity_at(&self, wall: usize, x: &P3) -> P3 {
        match self.pose(wall) {
            Some(now) if self.dt > 0.0 => (self.next[wall].place(&now.unplace(x)) - x) / self.dt,
            _ => P3::zeros(),
        }
    }

    /// The surface points of every wall as drawn (and of the domain box), at most `spacing` apart, with
    /// their normals into the wall.
    fn sample(&self, spacing: Real) -> Vec<BoundaryPoint<3>> {
        let (lo, hi) = (P3::zeros(), self.extent);
        let mut out = Vec::new();
        for i in 0..=self.walls.len() {
            let (solid, side) = if i == self.walls.len() {
                (&self.domain, Side::Inside)
            } else {
                (&self.walls[i].solid, self.walls[i].side)
            };
            // Into the wall: out of a container, into an obstacle.
            let into = match (solid, side) {
                (Solid::HalfSpace { .. }, _) | (_, Side::Inside) => 1.0,
                (_, Side::Outside) => -1.0,
            };
            for (x, [a, b, c]) in solid.surface(spacing, &lo, &hi) {
                out.push(BoundaryPoint::with_normals(x, [a * into, b * into, c * into], i));
            }
        }
        out
    }
}

impl Walls3 {
    /// A bound above wall `i`'s signed distance at `x` that costs nothing where it is a mesh obstacle
    /// whose bounding box is away from `x` (minus the distance to that box); none where only the exact
    /// value will do.
    fn distance_bound(&self, i: usize, x: &P3) -> Option<Real> {
        match self.walls.get(i) {
            Some(Wall3 { solid: Solid::Mesh(mesh), side: Side::Outside }) => {
                let local = self.pose(i).map_or(*x, |pose| pose.unplace(x));
                let away = mesh.bounds_distance(&wide(&local));
                (away > 0.0).then_some(-away as Real)
            }
            Some(Wall3 { solid: Solid::Shell { mesh, half }, .. }) => {
                let local = self.pose(i).map_or(*x, |pose| pose.unplace(x));
                let away = mesh.bounds_distance(&wide(&local)) - crate::math::wide(*half);
                (away > 0.0).then_some(-away as Real)
            }
            _ => None,
        }
    }

    /// [`Region::distance`] over every wall but `skip`: the largest signed distance, the first wall to
    /// reach it on a tie. Meshes come last, and one whose bound cannot reach the largest so far is not
    /// asked (its nearest-triangle search is the dear part).
    fn distance_except(&self, x: &P3, skip: Option<usize>) -> WallDistance<3> {
        let mut best = WallDistance { distance: Real::NEG_INFINITY, normal: P3::zeros(), wall: self.box_index() };
        let is_mesh =
            |i: usize| matches!(self.walls.get(i), Some(Wall3 { solid: Solid::Mesh(_) | Solid::Shell { .. }, .. }));
        let all = || (0..=self.walls.len()).filter(|&i| Some(i) != skip);
        for i in all().filter(|&i| !is_mesh(i)).chain(all().filter(|&i| is_mesh(i))) {
            if self.distance_bound(i, x).is_some_and(|bound| bound < best.distance) {
                continue;
            }
            let (d, n) = self.wall_distance(i)(x);
            if d > best.distance || (d == best.distance && i < best.wall) {
                best = WallDistance { distance: d, normal: n, wall: i };
            }
        }
        best
    }
}

impl Region<3> for Walls3 {
    /// Each wall's part multiplies (the material is on the material side of every wall). A box cuts the support
    /// by its three slabs, `Π_k (F((a_k − u_k)/h) − F((−a_k − u_k)/h))` in its own axes (`u` the node there, `a`
    /// the half extents; exact for a box along the grid's axes), its complement for an obstacle; any other solid
    /// by the plane at its signed distance.
    fn support_fraction(&self, x: &P3, h: Real) -> Real {
        use crate::kernel::bspline_integral as integral;
        let mut inside = 1.0;
        for i in 0..=self.walls.len() {
            let (solid, side) = if i == self.walls.len() {
                (&self.domain, Side::Inside)
            } else {
                (&self.walls[i].solid, self.walls[i].side)
            };
            let part = match solid {
                Solid::Box { centre, half, axes } => {
                    let x = self.pose(i).map_or(*x, |p| p.unplace(x));
                    let u = axes.transpose() * (x - centre);
                    let slabs: Real =
                        (0..3).map(|k| integral((half[k] - u[k]) / h) - integral((-half[k] - u[k]) / h)).product();
                    match side {
                        Side::Inside => slabs,
                        Side::Outside => 1.0 - slabs,
                    }
                }
                _ => integral(-self.wall_distance(i)(x).0 / h),
            };
            inside *= part;
            if inside == 0.0 {
                break;
            }
        }
        inside
    }

    fn distance(&self, x: &P3) -> WallDistance<3> {
        // Intersection of the material sides: the largest signed distance wins.
        self.distance_except(x, None)
    }

    fn wall_feet(&self, x: &P3, reach: Real) -> WallFeet<3> {
        let mut feet = WallFeet::default();
        let tolerance = Real::EPSILON.sqrt() * reach;
        for i in 0..=self.walls.len() {
            let (solid, side) = if i == self.walls.len() {
                (&self.domain, Side::Inside)
            } else {
                (&self.walls[i].solid, self.walls[i].side)
            };
            // A moving wall's feet are found in its drawing's frame and placed.
            let pose = self.pose(i);
            let x_drawn = pose.map_or(*x, |p| p.unplace(x));
            let mut add = |q: P3, normal: P3, curvature: Real| {
                let (q, normal, normal_next) = match pose {
                    Some(p) => (p.place(&q), p.turn(&normal), self.next[i].turn(&normal)),
                    None => (q, normal, normal),
                };
                let distance = (x - q).norm();
                // A face point counts only where it bounds the material region: on its own wall (up to
                // rounding, far below the tolerance), within no other.
                if distance < reach && self.distance_except(&q, Some(i)).distance <= tolerance {
                    let velocity = self.velocity_at(i, &q);
                    let foot = WallFoot { curvature, velocity, normal_next, ..WallFoot::still(q, normal, i) };
                    feet.push(foot, distance, tolerance);
                }
            };
            let x = &x_drawn;
            match (solid, side) {
                (Solid::HalfSpace { .. }, _) => solid.face_feet(x, &mut add),
                (Solid::Mesh(mesh), side) => {
                    let into = if side == Side::Inside { 1.0 } else { -1.0 };
                    mesh.feet(&wide(x), crate::math::wide(reach), into, |q, n| add(narrow(&q), narrow(&n), 0.0));
                }
                (Solid::Shell { mesh, half }, _) => {
                    let (reach, half) = (crate::math::wide(reach), crate::math::wide(*half));
                    mesh.shell_feet(&wide(x), reach, half, |q, n| add(narrow(&q), narrow(&n), 0.0));
                }
                (_, Side::Inside) => {
                    solid.face_feet(x, &mut add);
                    // Escaped past an edge or a corner (beyond two or three faces' extents): the nearest
                    // point of the container, on the edge or the corner, so that it goes no farther.
                    let (d, n) = solid.signed_distance(x);
                    if d > 0.0 {
                        add(x - n * d, n, 0.0);
                    }
                }
                (_, Side::Outside) => {
                    // An obstacle is convex: its nearest surface point, from outside or from within.
                    let (d, n) = solid.signed_distance(x);
                    add(x - n * d, -n, 0.0);
                }
            }
        }
        feet
    }

    fn boundary_points(&self, spacing: Real) -> Vec<BoundaryPoint<3>> {
        let mut out = if self.moves() {
            // Sampled once per spacing, as drawn; each step places the moving walls' points.
            let drawn = {
                let mut cache = self.drawn_points.lock().unwrap_or_else(|e| e.into_inner());
                match cache.iter().find(|(s, _)| *s == spacing) {
                    Some((_, drawn)) => drawn.clone(),
                    None => {
                        let drawn = std::sync::Arc::new(self.sample(spacing));
                        cache.push((spacing, drawn.clone()));
                        drawn
                    }
                }
            };
            let mut out = (*drawn).clone();
            for p in &mut out {
                if let Some(pose) = self.pose(p.wall) {
                    p.x = pose.place(&p.x);
                    p.normals = p.normals.map(|n| pose.turn(&n));
                    p.velocity = self.velocity_at(p.wall, &p.x);
                }
            }
            out
        } else {
            self.sample(spacing)
        };
        // Only points on the boundary of the material region are kept (a container's wall beyond a
        // half-space, or the domain box inside a container, is not), up to the rounding of a point.
        let tolerance = (1e-9 * spacing).max(16.0 * Real::EPSILON * self.extent.max());
        out.retain(|p| self.distance(&p.x).distance.abs() <= tolerance);
        out
    }

    fn moves(&self) -> bool {
        (0..self.walls.len()).any(|i| self.driven(i))
    }

    fn is_moving(&self, wall: usize) -> bool {
        self.driven(wall)
    }

    fn placement(&self, wall: usize) -> Option<Placement<3>> {
        let turn =
            |p: &Pose3| -> [Real; 3] { nalgebra::Rotation3::from_matrix_unchecked(p.rotation).scaled_axis().into() };
        let (now, next) = (self.pose(wall)?, &self.next[wall]);
        Some(Placement { pivot: now.pivot, offset: [now.offset, next.offset], turn: [turn(now), turn(next)] })
    }

    fn unposable(&self, wall: usize) -> Option<String> {
        matches!(self.walls[wall].solid, Solid::HalfSpace { .. })
            .then(|| format!("wall {wall} is a plane, which cannot move"))
    }

    fn set_poses(&mut self, poses: &[(usize, WallPose<3>)]) {
        self.set.fill(None);
        for &(wall, pose) in poses {
            self.set[wall] = Some(pose);
        }
    }

    fn pose_change(&self, wall: usize, pose: &WallPose<3>) -> (Real, Real) {
        let pivot = self.pivot(wall);
        let reach = self.walls[wall].solid.reach_from(&pivot);
        (self.now[wall].distance_to(&pose.pose3(pose.time, pivot), reach), pose.top_speed(reach))
    }

    fn sweep(&self) -> Real {
        self.sweep
    }

    fn set_time(&mut self, t: Real, dt: Real) {
        self.dt = dt;
        self.sweep = 0.0;
        for i in 0..self.walls.len() {
            let pivot = self.pivot(i);
            let before = self.now[i];
            (self.now[i], self.next[i]) = match (&self.set[i], &self.moves[i]) {
                (Some(set), _) => (set.pose3(t, pivot), set.pose3(t + dt, pivot)),
                (None, Some(motion)) => {
                    let centre = self.walls[i].solid.centre();
                    (motion.pose(t, centre), motion.pose(t + dt, centre))
                }
                // Still, or back where it is drawn (a restored state without the pose it had been set).
                (None, None) => (Pose3::still(pivot), Pose3::still(pivot)),
            };
            if self.now[i] != before {
                let moved = before.distance_to(&self.now[i], self.walls[i].solid.reach_from(&before.pivot));
                self.sweep = if moved.is_nan() { Real::INFINITY } else { self.sweep.max(moved) };
            }
        }
    }

    fn surface_velocity(&self, wall: usize, x: &P3, _n: &P3) -> P3 {
        self.velocity_at(wall, x)
    }

    fn num_walls(&self) -> usize {
        self.walls.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::Motion3;
    use nalgebra::{Rotation3, Unit};

    /// A few deterministic pseudo-random numbers in [0, 1).
    fn uniform(n: usize) -> Vec<Real> {
        let mut s = 0x2545f4914f6cdd1du64;
        (0..n)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                (s >> 11) as Real / (1u64 << 53) as Real
            })
            .collect()
    }

    fn tilted_box() -> Solid {
        let axes = Rotation3::from_axis_angle(&Unit::new_normalize(P3::new(1.0, 2.0, 0.5)), 0.4).into_inner();
        Solid::Box { centre: P3::new(0.5, 0.45, 0.5), half: P3::new(0.3, 0.25, 0.2), axes }
    }

    fn solids() -> Vec<Solid> {
        vec![
            Solid::HalfSpace { point: P3::new(0.5, 0.2, 0.5), normal: P3::new(0.3, -1.0, 0.2).normalize() },
            tilted_box(),
            Solid::Sphere { centre: P3::new(0.5, 0.5, 0.45), radius: 0.3 },
            Solid::Cylinder {
                centre: P3::new(0.5, 0.5, 0.5),
                axis: P3::new(0.2, 1.0, -0.3).normalize(),
                radius: 0.2,
                half_length: 0.25,
            },
        ]
    }

    /// Each solid's signed distance is its exact distance to the surface: the normal is its gradient
    /// (central differences within 1e-6 away from edges) and stepping back along the normal by the
    /// distance lands on the surface.
    #[test]
    fn signed_distances_are_distances() {
        let r = uniform(3 * 400);
        for solid in solids() {
            for k in 0..400 {
                let x = P3::new(r[3 * k], r[3 * k + 1], r[3 * k + 2]);
                let (d, n) = solid.signed_distance(&x);
                let on = x - n * d;
                assert!(solid.signed_distance(&on).0.abs() < 1e-12, "{solid:?} at {x}");
                let e = 1e-7;
                let grad = P3::from_fn(|a, _| {
                    let mut s = P3::zeros();
                    s[a] = e;
                    (solid.signed_distance(&(x + s)).0 - solid.signed_distance(&(x - s)).0) / (2.0 * e)
                });
                // Away from the medial surfaces, where the distance has a kink.
                if (grad.norm() - 1.0).abs() < 1e-6 {
                    assert!((grad - n).norm() < 1e-5, "{solid:?} at {x}: {grad} vs {n}");
                }
            }
        }
    }

    /// Boundary points lie on the surfaces of the region, face into the wall, and cover it: every
    /// surface point (of a container tilted in no coordinate plane, a sphere and a cylinder inside the
    /// domain) is within h of a boundary point, and no two boundary points coincide.
    #[test]
    fn boundary_points_cover_the_surfaces_at_spacing_h() {
        let h = 1.0 / 32.0;
        let r = uniform(3 * 3000);
        for solid in solids().into_iter().skip(1) {
            let walls = Walls3::new(vec![Wall3 { solid: solid.clone(), side: Side::Inside }], P3::new(1.0, 1.0, 1.0));
            let points: Vec<_> = walls.boundary_points(h).into_iter().filter(|p| p.wall == 0).collect();
            for p in &points {
                let (d, n) = solid.signed_distance(&p.x);
                assert!(d.abs() < 1e-12, "{solid:?}: {:?} off the surface", p.x);
                assert!(p.normals.iter().all(|m| m.dot(&n) > -1e-12), "{solid:?}: normals out of the solid");
            }
            for k in 0..3000 {
                let x = P3::new(r[3 * k], r[3 * k + 1], r[3 * k + 2]);
                let (d, n) = solid.signed_distance(&x);
                let on = x - n * d;
                let nearest = points.iter().map(|p| (p.x - on).norm()).fold(Real::INFINITY, Real::min);
                assert!(nearest <= h, "{solid:?}: {on} is {} h from a boundary point", nearest / h);
            }
            let mut xs: Vec<[Real; 3]> = points.iter().map(|p| [p.x.x, p.x.y, p.x.z]).collect();
            xs.sort_by(|a, b| a.partial_cmp(b).unwrap());
            assert!(xs.windows(2).all(|w| w[0] != w[1]), "{solid:?}: a point twice");
        }
    }

    /// A particle near a corner of a tilted box container has a foot on each of the three faces, each
    /// with the face's outward normal, and one that escaped past the corner a foot on it; one just outside
    /// a box obstacle's edge has its foot on the edge.
    #[test]
    fn feet_on_the_faces_in_reach() {
        let Solid::Box { centre, half, axes } = tilted_box() else { unreachable!() };
        let walls = Walls3::new(vec![Wall3 { solid: tilted_box(), side: Side::Inside }], P3::new(1.0, 1.0, 1.0));
        let corner = centre + axes * half;
        let x = centre + axes * (half - P3::new(0.01, 0.02, 0.015));
        let feet = walls.wall_feet(&x, 0.05);
        assert_eq!(feet.len(), 3);
        for f in feet.iter() {
            assert!((f.x - corner).dot(&f.normal).abs() < 1e-12 && f.normal.dot(&(f.x - x)) > 0.0);
        }
        // Escaped past the corner (beyond all three faces' extents): a foot on the corner itself.
        let x = centre + axes * (half + P3::new(0.01, 0.01, 0.01));
        let feet = walls.wall_feet(&x, 0.05);
        assert!(feet.iter().any(|f| (f.x - corner).norm() < 1e-12), "a foot on the corner");
        let obstacle = Walls3::new(vec![Wall3 { solid: tilted_box(), side: Side::Outside }], P3::new(1.0, 1.0, 1.0));
        let edge = centre + axes * P3::new(half.x, half.y, 0.0);
        let x = edge + axes * P3::new(0.01, 0.01, 0.0);
        let feet = obstacle.wall_feet(&x, 0.05);
        let foot = feet.iter().next().expect("a foot");
        assert!((foot.x - edge).norm() < 1e-12 && (foot.normal + (x - edge).normalize()).norm() < 1e-12);
    }

    /// With meshes (a sphere mesh obstacle, a thin plate, one of them moving), the region's distance (meshes
    /// last, skipped where their bounding box says they cannot win) is the largest of all walls' distances,
    /// the first wall on a tie, at random points.
    #[test]
    fn skipping_meshes_by_their_boxes_changes_no_distance() {
        use crate::mesh::shapes::icosphere;
        let (v, t) = icosphere([0.4, 0.5, 0.5], 0.15, 2);
        let ball = Arc::new(TriangleMesh::new(&v, &t, 0.5).expect("closed"));
        let plate = [[0.6, 0.2, 0.2], [0.9, 0.3, 0.2], [0.9, 0.4, 0.8], [0.6, 0.3, 0.8]];
        let plate = Arc::new(TriangleMesh::open(&plate, &[[0, 1, 2], [0, 2, 3]]).expect("open"));
        let walls = vec![
            Wall3 { solid: tilted_box(), side: Side::Inside },
            Wall3 { solid: Solid::Mesh(ball), side: Side::Outside },
            Wall3 { solid: Solid::Shell { mesh: plate, half: 0.04 }, side: Side::Outside },
        ];
        let spin = Motion3::Constant { velocity: [0.1, 0.0, 0.0], angular_velocity: [0.0, 1.0, 0.5], pivot: None };
        let mut region =
            Walls3::new(walls, P3::new(1.0, 1.0, 1.0)).with_moves(vec![None, Some(spin), None]).expect("moves");
        region.set_time(0.3, 1e-3);
        let r = uniform(3 * 3000);
        for k in 0..3000 {
            let x = P3::new(r[3 * k], r[3 * k + 1], r[3 * k + 2]);
            let got = region.distance(&x);
            let (mut best, mut wall) = (Real::NEG_INFINITY, usize::MAX);
            for i in 0..=region.walls.len() {
                let d = region.wall_distance(i)(&x).0;
                if d > best {
                    (best, wall) = (d, i);
                }
            }
            assert!(got.distance == best && got.wall == wall, "{x}: {got:?} vs {best} at wall {wall}");
        }
    }
}
