//! 2D wall geometry: polygons, circles and the material region they bound.
//!
//! Distances are signed and positive on the wall side (outside the material);
//! normals point from the material into the wall.

use crate::kernel::bspline_integral;
use crate::math::{Real, Vector};
use crate::motion::{Motion, Pose, WallPose};
use crate::wall::BoundaryPoint;
use nalgebra::Vector2;

pub type Point = Vector2<Real>;

/// Signed distance to the nearest wall and the wall it belongs to.
#[derive(Clone, Copy, Debug)]
pub struct WallDistance<const D: usize> {
    /// Signed distance (m): positive outside the material region.
    pub distance: Real,
    /// Unit normal pointing out of the material, into the wall.
    pub normal: Vector<D>,
    /// Index of the wall in [`Region::walls`] order.
    pub wall: usize,
}

/// The closest point of one wall face to a particle (the foot of the perpendicular).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WallFoot<const D: usize> {
    /// Position on the wall (m).
    pub x: Vector<D>,
    /// Unit normal of the face there, out of the material, into the wall.
    pub normal: Vector<D>,
    /// Index of the wall in [`Region::distance`] order.
    pub wall: usize,
    /// Velocity of the wall surface there (m/s): of a still wall only its tangential part acts, of a
    /// moving one all of it.
    pub velocity: Vector<D>,
    /// 1/radius (1/m) of a face that curves around the material (a circular container); 0 for a
    /// straight face and for one that curves away from the material (an obstacle).
    pub curvature: Real,
    /// Velocity (m/s) of the face's centre of curvature as the wall moves (zero for a still wall): what
    /// a particle's motion along a curved face is measured against.
    pub centre_velocity: Vector<D>,
    /// The face's normal at the end of the step (a turning wall turns it; `normal` for a still one): a
    /// particle on a straight face that moves with it must end the step on the face where it is then.
    pub normal_next: Vector<D>,
    /// How far (m) the particle lies past the face (negative: inside it) where [`WallFeet::pin_past`]
    /// pinned the foot to the particle; −∞ where it did not.
    pub depth: Real,
}

impl<const D: usize> WallFoot<D> {
    /// Whether [`WallFeet::pin_past`] pinned the foot to its particle (past the face or within the margin).
    pub fn is_pinned(&self) -> bool {
        self.depth > Real::NEG_INFINITY
    }

    /// A foot at `x` on a still straight face of wall `wall` whose normal (into the wall) is `normal`.
    pub fn still(x: Vector<D>, normal: Vector<D>, wall: usize) -> Self {
        let zero = Vector::<D>::zeros();
        Self {
            x,
            normal,
            wall,
            velocity: zero,
            curvature: 0.0,
            centre_velocity: zero,
            normal_next: normal,
            depth: Real::NEG_INFINITY,
        }
    }
}

/// Most wall faces a particle takes into account at once (a corner has two; a narrow gap more).
pub const MAX_FEET: usize = 4;

/// The feet of the wall faces in reach of one particle: the [`MAX_FEET`] nearest.
#[derive(Clone, Copy, Debug)]
pub struct WallFeet<const D: usize> {
    len: usize,
    feet: [Option<WallFoot<D>>; MAX_FEET],
    /// Distance (m) from the particle to each foot.
    distance: [Real; MAX_FEET],
}

impl<const D: usize> Default for WallFeet<D> {
    fn default() -> Self {
        Self { len: 0, feet: [None; MAX_FEET], distance: [0.0; MAX_FEET] }
    }
}

impl<const D: usize> WallFeet<D> {
    /// Adds a foot at `distance` (m) from the particle unless the same face point is already there
    /// (a polygon edge lying on the domain box); when the list is full, it replaces the farthest
    /// foot if it is nearer.
    pub fn push(&mut self, foot: WallFoot<D>, distance: Real, tolerance: Real) {
        let same = |f: &WallFoot<D>| (f.x - foot.x).norm() <= tolerance && f.normal.dot(&foot.normal) > 1.0 - 1e-6;
        if self.iter().any(same) {
            return;
        }
        let slot = if self.len < MAX_FEET {
            self.len += 1;
            self.len - 1
        } else {
            let far = (0..MAX_FEET).max_by(|&a, &b| self.distance[a].total_cmp(&self.distance[b])).unwrap_or(0);
            if self.distance[far] <= distance {
                return;
            }
            far
        };
        self.feet[slot] = Some(foot);
        self.distance[slot] = distance;
    }

    pub fn iter(&self) -> impl Iterator<Item = &WallFoot<D>> {
        self.feet[..self.len].iter().flatten()
    }

    /// For a particle at `x` that lies past the walls or within `margin` (m) of them: moves the foot of
    /// each face it lies past, or within `margin` of, to `x` itself, so that the fit meets that face's
    /// condition at the particle. At the foot behind it the fit would leave the particle a normal velocity
    /// `r n·C n` outward (r its depth), and a normal strain rate that persists (a lone particle sliding
    /// along a ceiling keeps its C) would carry it out exponentially from wherever rounding put it; one
    /// sliding on a face would step in and out of it by rounding.
    /// Its depth past the face (negative within the margin) is kept in `depth`.
    pub fn pin_past(&mut self, x: &Vector<D>, margin: Real) {
        for foot in self.feet[..self.len].iter_mut().flatten() {
            let depth = (x - foot.x).dot(&foot.normal);
            if depth >= -margin {
                foot.x = *x;
                foot.depth = depth;
            }
        }
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

/// Where a moving wall is over a step: its drawing turned about `pivot` (m, where the scene draws it) by
/// `turn` (a rotation vector, rad; about z in 2D) and displaced by `offset` (m), at the step's start
/// (`[0]`) and end (`[1]`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement<const D: usize> {
    pub pivot: Vector<D>,
    pub offset: [Vector<D>; 2],
    pub turn: [[Real; 3]; 2],
}

/// Nodes whose support lies less than this much inside the material are left out of the densities and packings
/// gathered from the grid.
pub const MIN_WALL_FRACTION: Real = 0.3;

/// Half the width (cells) of the quadratic B-spline's support along an axis.
pub const SUPPORT_REACH: Real = 1.5;

/// A region the material may occupy, bounded by walls.
pub trait Region<const D: usize>: Send + Sync {
    fn distance(&self, x: &Vector<D>) -> WallDistance<D>;

    /// The feet on the wall faces that bound the region within `reach` (m) of `x`: on each
    /// straight face whose perpendicular from `x` lands inside it, at each corner `x` lies past
    /// both faces of (a reflex corner seen from inside, or a convex one from a particle that has
    /// left the region), and on each circle. A region without walls has none.
    fn wall_feet(&self, _x: &Vector<D>, _reach: Real) -> WallFeet<D> {
        WallFeet::default()
    }

    /// Whether any wall moves.
    fn moves(&self) -> bool {
        false
    }

    /// The part of the quadratic B-spline support of a node at `x` that lies inside the material, for cells of
    /// width `h` (m). Here each wall face within reach cuts the support by a plane: a plane `s` past the node
    /// leaves `F(−s/h)` of it, F the integral of the spline ([`crate::kernel::bspline_integral`]), and the faces'
    /// parts multiply. Without a face in reach, the plane at the signed distance.
    fn support_fraction(&self, x: &Vector<D>, h: Real) -> Real {
        let d = self.distance(x).distance;
        if d <= -SUPPORT_REACH * h {
            return 1.0;
        }
        if d >= SUPPORT_REACH * h {
            return 0.0;
        }
        let feet = self.wall_feet(x, SUPPORT_REACH * h);
        if feet.is_empty() {
            return bspline_integral(-d / h);
        }
        feet.iter().map(|foot| bspline_integral(-(x - foot.x).dot(&foot.normal) / h)).product()
    }

    /// Number of walls, the domain box not counted.
    fn num_walls(&self) -> usize {
        0
    }

    /// Sets the poses of the walls that `poses` names (wall, pose), sorted by wall; the others
    /// move as their scene says. Takes effect at the next [`Region::set_time`].
    fn set_poses(&mut self, _poses: &[(usize, WallPose<D>)]) {}

    /// Why wall `wall` cannot be posed from outside, if it cannot (a wall that does not move in any
    /// pose, such as an endless plane).
    fn unposable(&self, _wall: usize) -> Option<String> {
        None
    }

    /// How far (m) a point of wall `wall` jumps from where it is now to where `pose` puts it at
    /// `pose.time`, and the top speed (m/s) of its points in that pose.
    fn pose_change(&self, _wall: usize, _pose: &WallPose<D>) -> (Real, Real) {
        (0.0, 0.0)
    }

    /// Puts the moving walls where they are at time `t` (s), moving at their velocities over the
    /// step `dt` (s) that starts there. Still walls stay.
    fn set_time(&mut self, _t: Real, _dt: Real) {}

    /// A bound on how far (m) any wall point moved at the last [`Region::set_time`]: no signed distance
    /// changed by more (infinite when unknown).
    fn sweep(&self) -> Real {
        Real::INFINITY
    }

    /// Velocity (m/s) of wall `wall`'s surface near `x`, where its outward normal is `n`.
    fn surface_velocity(&self, _wall: usize, _x: &Vector<D>, _n: &Vector<D>) -> Vector<D> {
        Vector::<D>::zeros()
    }

    /// Points sampled along the walls at most `spacing` (m) apart, each with its wall's velocity there:
    /// the boundary points of an augmented grid. A region that does not sample its walls has none.
    fn boundary_points(&self, _spacing: Real) -> Vec<BoundaryPoint<D>> {
        Vec::new()
    }

    /// Each wall where it is now, as a closed outline (its vertices; a circle as 64 points), for drawing.
    fn outlines(&self) -> Vec<Vec<Vector<D>>> {
        Vec::new()
    }

    /// Where wall `wall` is over the step of the last [`Region::set_time`], if it moves.
    fn placement(&self, _wall: usize) -> Option<Placement<D>> {
        None
    }

    /// Whether wall `wall` moves.
    fn is_moving(&self, _wall: usize) -> bool {
        false
    }
}

/// The part of a node's support on the inner side of every one of several cuts, each `(g, n)`: the part `g` on
/// its inner side and its outward unit normal `n`. Cuts along one line keep the smaller part, and cuts facing
/// each other across a slab keep `max(0, g₁ + g₂ − 1)` (both exact); the groups so formed then join one by one,
/// each with the group before whose normal is most nearly parallel or opposite to its own, as the bounds for two
/// correlated cuts do, blended linearly in `ρ = n₁·n₂`: `g₁g₂` for perpendicular normals (exact along the grid's
/// axes), toward `min(g₁, g₂)` as ρ → 1 and toward `max(0, g₁ + g₂ − 1)` as ρ → −1.
pub fn intersect_cuts(cuts: impl Iterator<Item = (Real, Point)>) -> Real {
    const MAX: usize = 8;
    const PARALLEL: Real = 0.999;
    // Groups of cuts along one direction: (normal, the part on the inner side of the group's cuts).
    let (mut groups, mut count) = ([(Point::zeros(), 1.0 as Real); MAX], 0);
    for (g, n) in cuts {
        match groups[..count].iter_mut().find(|(m, _)| m.dot(&n).abs() > PARALLEL) {
            Some((m, inside)) if m.dot(&n) > 0.0 => *inside = inside.min(g),
            Some((_, inside)) => *inside = (*inside + g - 1.0).max(0.0),
            None if count < MAX => {
                groups[count] = (n, g);
                count += 1;
            }
            None => groups[count - 1].1 *= g,
        }
    }
    let mut inside = 1.0;
    for (k, &(n, g)) in groups[..count].iter().enumerate() {
        let rho = groups[..k].iter().map(|(m, _)| m.dot(&n)).max_by(|a, b| a.abs().total_cmp(&b.abs()));
        let independent = inside * g;
        inside = match rho {
            None => g,
            Some(rho) if rho >= 0.0 => independent + rho * (inside.min(g) - independent),
            Some(rho) => independent - rho * ((inside + g - 1.0).max(0.0) - independent),
        };
    }
    inside
}

/// A closed polygon given counter-clockwise.
#[derive(Clone, Debug, PartialEq)]
pub struct Polygon {
    pub vertices: Vec<Point>,
}

impl Polygon {
    pub fn new(vertices: Vec<Point>) -> Self {
        Self { vertices }
    }

    pub fn edges(&self) -> impl Iterator<Item = (Point, Point)> + '_ {
        let n = self.vertices.len();
        (0..n).map(move |i| (self.vertices[i], self.vertices[(i + 1) % n]))
    }

    /// Signed area (m²): positive for counter-clockwise vertices (shoelace formula).
    pub fn signed_area(&self) -> Real {
        0.5 * self.edges().map(|(a, b)| a.x * b.y - b.x * a.y).sum::<Real>()
    }

    /// Point-in-polygon by the even–odd crossing rule.
    pub fn contains(&self, p: &Point) -> bool {
        let mut inside = false;
        for (a, b) in self.edges() {
            if (a.y > p.y) != (b.y > p.y) {
                let x = a.x + (p.y - a.y) / (b.y - a.y) * (b.x - a.x);
                if p.x < x {
                    inside = !inside;
                }
            }
        }
        inside
    }

    /// Signed distance (positive outside) and the outward unit normal of the nearest boundary point.
    pub fn signed_distance(&self, p: &Point) -> (Real, Point) {
        let mut best = (Real::INFINITY, Point::zeros(), Point::zeros());
        for (a, b) in self.edges() {
            let e = b - a;
            let t = ((p - a).dot(&e) / e.norm_squared()).clamp(0.0, 1.0);
            let q = a + e * t;
            let d = (p - q).norm();
            if d < best.0 {
                // Outward normal of a CCW edge (a → b) is the edge turned clockwise.
                best = (d, q, Point::new(e.y, -e.x).normalize());
            }
        }
        let (d, q, edge_normal) = best;
        let inside = self.contains(p);
        // Away from the wall, the direction to the nearest point is the true normal
        // (also at corners); on the wall itself fall back to the edge normal.
        // (On the wall up to rounding: ~1e-7 m in f32 for coordinates of order 1 m.)
        let on_wall = (1e-12 as Real).max(16.0 * Real::EPSILON * (p.amax() + 1.0));
        let normal = if d > on_wall {
            let n = (p - q) / d;
            if inside {
                -n
            } else {
                n
            }
        } else {
            edge_normal
        };
        (if inside { -d } else { d }, normal)
    }

    /// The part of the quadratic B-spline support of a node at `p` (cells of width `h`, m) that lies inside the
    /// polygon. Each edge whose segment comes within the support's reach cuts it along its line: `g = F(−s/h)` of
    /// the support lies on the inner side, `s` the signed distance to the line (positive outside). Inside a convex
    /// polygon the cuts intersect ([`intersect_cuts`]: exact for edges along the grid's axes, and for parallel
    /// edges on a line or facing each other); at a vertex of a polygon that is not convex, two edges intersect at
    /// a convex vertex and join at a reflex one; elsewhere the plane at the signed distance.
    pub fn support_inside(&self, p: &Point, h: Real) -> Real {
        const MAX_CUTS: usize = 8;
        let reach = SUPPORT_REACH * std::f64::consts::SQRT_2 as Real * h;
        let n = self.vertices.len();
        let (mut cuts, mut count) = ([(0usize, 0.0 as Real, Point::zeros()); MAX_CUTS], 0);
        for (k, (a, b)) in self.edges().enumerate() {
            let e = b - a;
            let t = ((p - a).dot(&e) / e.norm_squared()).clamp(0.0, 1.0);
            if (p - (a + e * t)).norm() <= reach {
                if count == MAX_CUTS {
                    return bspline_integral(-self.signed_distance(p).0 / h);
                }
                let outward = Point::new(e.y, -e.x).normalize();
                cuts[count] = (k, bspline_integral(-(p - a).dot(&outward) / h), outward);
                count += 1;
            }
        }
        let cuts = &cuts[..count];
        let turn = |k: usize| {
            // The turn at the vertex where edge k ends: positive at a convex vertex of a counter-clockwise polygon.
            let (a, b, c) = (self.vertices[k], self.vertices[(k + 1) % n], self.vertices[(k + 2) % n]);
            let (u, v) = (b - a, c - b);
            u.x * v.y - u.y * v.x
        };
        match cuts {
            [] => Real::from(u8::from(self.contains(p))),
            [(_, g, _)] => *g,
            _ if (0..n).all(|k| turn(k) >= 0.0) => intersect_cuts(cuts.iter().map(|&(_, g, normal)| (g, normal))),
            [(i, gi, ni), (j, gj, nj)] if (i + 1) % n == *j || (j + 1) % n == *i => {
                let first = if (i + 1) % n == *j { *i } else { *j };
                if turn(first) >= 0.0 {
                    intersect_cuts([(*gi, *ni), (*gj, *nj)].into_iter())
                } else {
                    // The union: what lies outside both, the intersection of the complements, left out.
                    1.0 - intersect_cuts([(1.0 - gi, -ni), (1.0 - gj, -nj)].into_iter())
                }
            }
            _ => bspline_integral(-self.signed_distance(p).0 / h),
        }
    }

    /// First pair of non-adjacent edges that intersect, if any.
    pub fn self_intersection(&self) -> Option<(usize, usize)> {
        let n = self.vertices.len();
        for i in 0..n {
            for j in i + 1..n {
                let adjacent = j == i + 1 || (i == 0 && j == n - 1);
                if adjacent {
                    continue;
                }
                let (a, b) = (self.vertices[i], self.vertices[(i + 1) % n]);
                let (c, d) = (self.vertices[j], self.vertices[(j + 1) % n]);
                if segments_intersect(&a, &b, &c, &d) {
                    return Some((i, j));
                }
            }
        }
        None
    }
}

fn orient(a: &Point, b: &Point, c: &Point) -> Real {
    (b - a).perp(&(c - a))
}

fn on_segment(a: &Point, b: &Point, p: &Point) -> bool {
    p.x >= a.x.min(b.x) && p.x <= a.x.max(b.x) && p.y >= a.y.min(b.y) && p.y <= a.y.max(b.y)
}

/// Closed-segment intersection test (touching counts).
pub fn segments_intersect(a: &Point, b: &Point, c: &Point, d: &Point) -> bool {
    let (o1, o2) = (orient(a, b, c), orient(a, b, d));
    let (o3, o4) = (orient(c, d, a), orient(c, d, b));
    if ((o1 > 0.0 && o2 < 0.0) || (o1 < 0.0 && o2 > 0.0)) && ((o3 > 0.0 && o4 < 0.0) || (o3 < 0.0 && o4 > 0.0)) {
        return true;
    }
    (o1 == 0.0 && on_segment(a, b, c))
        || (o2 == 0.0 && on_segment(a, b, d))
        || (o3 == 0.0 && on_segment(c, d, a))
        || (o4 == 0.0 && on_segment(c, d, b))
}

/// Which side of a circular wall the material lives on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// The circle is an obstacle; material outside it.
    Outside,
    /// The circle is a container; material inside it.
    Inside,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Circle {
    pub center: Point,
    pub radius: Real,
}

impl Circle {
    pub fn contains(&self, p: &Point) -> bool {
        (p - self.center).norm() < self.radius
    }

    /// Signed distance to the circle, positive outside it, and the outward normal.
    pub fn signed_distance(&self, p: &Point) -> (Real, Point) {
        let r = p - self.center;
        let n = r.norm();
        let normal = if n > 1e-300 { r / n } else { Point::new(1.0, 0.0) };
        (n - self.radius, normal)
    }
}

/// An open polyline drawn `2·half` (m) wide: the points within `half` of it, with round ends and
/// joints. Material lies all around it: a plate, a ramp, a paddle.
#[derive(Clone, Debug, PartialEq)]
pub struct Stroke {
    /// The centreline, at least two distinct consecutive points.
    pub vertices: Vec<Point>,
    pub half: Real,
}

impl Stroke {
    /// Where `p`'s perpendicular lands on segment `k`, as a fraction of its length.
    fn along(&self, k: usize, p: &Point) -> Real {
        let (a, b) = (self.vertices[k], self.vertices[k + 1]);
        (p - a).dot(&(b - a)) / (b - a).norm_squared()
    }

    /// The unit normal of segment `k`, to its left.
    fn left(&self, k: usize) -> Point {
        let e = (self.vertices[k + 1] - self.vertices[k]).normalize();
        Point::new(-e.y, e.x)
    }

    /// Signed distance to the stroke's surface, negative inside it, and the outward normal there
    /// (from the centreline towards `p`).
    pub fn signed_distance(&self, p: &Point) -> (Real, Point) {
        let (mut best, mut normal) = (Real::INFINITY, self.left(0));
        for k in 0..self.vertices.len() - 1 {
            let a = self.vertices[k];
            let q = a + (self.vertices[k + 1] - a) * self.along(k, p).clamp(0.0, 1.0);
            let r = p - q;
            let d = r.norm();
            if d < best {
                best = d;
                normal = if d > 1e-300 { r / d } else { self.left(k) };
            }
        }
        (best - self.half, normal)
    }

    /// Points along the stroke's surface at most `spacing` (m) apart, with the outward normal at each,
    /// walked clockwise around it: the left side forward, the round end, the right side back, the round
    /// start. Where the centreline turns, the outer side gets an arc and the inner side's offset lines
    /// cross (their points past the crossing lie inside the stroke).
    pub fn surface(&self, spacing: Real) -> Vec<(Point, Point)> {
        let m = self.vertices.len();
        let mut out = Vec::new();
        let side = |from: Point, to: Point, n: Point, out: &mut Vec<(Point, Point)>| {
            let parts = ((to - from).norm() / spacing).ceil().max(1.0) as usize;
            out.extend((0..parts).map(|k| (from + (to - from) * (k as Real / parts as Real), n)));
        };
        // The arc about `c` from outward normal `n`, turning clockwise by `sweep` (rad), its end left out.
        let arc = |c: Point, n: Point, sweep: Real, out: &mut Vec<(Point, Point)>| {
            let parts = (sweep * self.half / spacing).ceil() as usize;
            out.extend((0..parts).map(|k| {
                let (s, co) = (-sweep * k as Real / parts as Real).sin_cos();
                let r = Point::new(co * n.x - s * n.y, s * n.x + co * n.y);
                (c + r * self.half, r)
            }));
        };
        // The clockwise turn (rad, ≥ 0) from direction `a` to direction `b`; 0 for a left turn.
        let right_turn = |a: Point, b: Point| (-a.perp(&b).atan2(a.dot(&b))).max(0.0);
        let dir = |k: usize| (self.vertices[k + 1] - self.vertices[k]).normalize();
        let pi = crate::math::PI;
        for k in 0..m - 1 {
            let n = self.left(k);
            side(self.vertices[k] + n * self.half, self.vertices[k + 1] + n * self.half, n, &mut out);
            if k + 2 < m {
                arc(self.vertices[k + 1], n, right_turn(dir(k), dir(k + 1)), &mut out);
            }
        }
        arc(self.vertices[m - 1], self.left(m - 2), pi, &mut out);
        for k in (0..m - 1).rev() {
            let n = -self.left(k);
            side(self.vertices[k + 1] + n * self.half, self.vertices[k] + n * self.half, n, &mut out);
            if k > 0 {
                arc(self.vertices[k], n, right_turn(-dir(k), -dir(k - 1)), &mut out);
            }
        }
        arc(self.vertices[0], -self.left(0), pi, &mut out);
        out
    }
}

/// How the surface of one wall moves (its geometry stays still).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceMotion {
    /// Velocity of the surface (m/s); only its part along the wall acts.
    pub velocity: Point,
    /// Speed along the wall (m/s): counter-clockwise along a polygon, or around a circle's centre.
    pub tangential_speed: Real,
    /// Centre of a circular wall.
    pub center: Option<Point>,
}

impl SurfaceMotion {
    /// A wall whose surface does not move.
    pub const STILL: Self = Self { velocity: Point::new(0.0, 0.0), tangential_speed: 0.0, center: None };

    /// Surface velocity (m/s) near `x`, where the wall's outward normal is `n`.
    pub fn at(&self, x: &Point, n: &Point) -> Point {
        let tangent = match self.center {
            Some(c) => {
                let r = x - c;
                let norm = r.norm();
                if norm > 0.0 {
                    Point::new(-r.y, r.x) / norm
                } else {
                    Point::zeros()
                }
            }
            // Counter-clockwise along a polygon whose material is inside: the normal turned left.
            None => Point::new(-n.y, n.x),
        };
        self.velocity + tangent * self.tangential_speed
    }
}

/// Geometry of one wall.
#[derive(Clone, Debug, PartialEq)]
pub enum WallShape {
    /// Material inside the (counter-clockwise) polygon: a container.
    Polygon(Polygon),
    /// Material outside the (counter-clockwise) polygon: an obstacle.
    Obstacle(Polygon),
    /// A circle, material on the given side.
    Circle(Circle, Side),
    /// An open polyline with a width, material around it.
    Stroke(Stroke),
}

/// The material region of a 2D scene: inside the domain box, inside the union
/// of the polygon walls (if any) and on the material side of every circle.
/// Wall `i < walls.len()` is a scene wall; index `walls.len()` is the domain box.
#[derive(Clone, Debug)]
pub struct Walls2 {
    /// Each wall where it is now.
    pub walls: Vec<WallShape>,
    domain_box: Polygon,
    /// How each wall's surface moves, the domain box last (still).
    motions: Vec<SurfaceMotion>,
    /// Each wall as the scene draws it, and how it moves (`None`: still).
    drawn: Vec<WallShape>,
    moves: Vec<Option<Motion>>,
    /// Poses set from outside (`Simulation::set_wall_pose`), which take over from `moves`.
    set: Vec<Option<WallPose<2>>>,
    /// Each moving wall's pose now and at the end of the step, and the step (s).
    now: Vec<Pose>,
    next: Vec<Pose>,
    dt: Real,
    /// How far (m) any wall point moved at the last `set_time`, at most.
    sweep: Real,
}

impl Walls2 {
    /// Walls whose surfaces are still.
    pub fn new(walls: Vec<WallShape>, extent: Point) -> Self {
        let domain_box = Polygon::new(vec![
            Point::new(0.0, 0.0),
            Point::new(extent.x, 0.0),
            Point::new(extent.x, extent.y),
            Point::new(0.0, extent.y),
        ]);
        let motions = vec![SurfaceMotion::STILL; walls.len() + 1];
        let still: Vec<Pose> = walls.iter().map(|w| Pose::still(w.centre())).collect();
        let (moves, set) = (vec![None; walls.len()], vec![None; walls.len()]);
        let drawn = walls.clone();
        Self { drawn, walls, domain_box, motions, moves, set, now: still.clone(), next: still, dt: 0.0, sweep: 0.0 }
    }

    /// The same walls, wall `i` moving as `moves[i]` says (`None`: still), placed at time 0.
    pub fn with_moves(mut self, moves: Vec<Option<Motion>>) -> Self {
        assert_eq!(moves.len(), self.walls.len(), "one motion per wall");
        self.moves = moves;
        self.set_time(0.0, 0.0);
        self
    }

    /// Whether wall `wall` moves (by its motion or a pose set from outside).
    pub fn is_moving(&self, wall: usize) -> bool {
        self.moves.get(wall).is_some_and(Option::is_some) || self.set.get(wall).is_some_and(Option::is_some)
    }

    /// The point wall `wall` turns about, where the scene draws it: its motion's pivot, else its centre.
    pub fn pivot(&self, wall: usize) -> Point {
        self.moves[wall]
            .as_ref()
            .and_then(Motion::pivot)
            .map_or_else(|| self.drawn[wall].centre(), |p| Point::new(p[0], p[1]))
    }

    /// The farthest distance (m) of wall `wall` from its pivot.
    pub fn reach(&self, wall: usize) -> Real {
        self.drawn[wall].reach_from(&self.pivot(wall))
    }

    /// Wall `wall` as the scene draws it.
    pub fn drawn(&self, wall: usize) -> &WallShape {
        &self.drawn[wall]
    }

    /// The domain box, a container.
    pub fn domain_box(&self) -> &Polygon {
        &self.domain_box
    }

    /// The pose of wall `wall` now.
    pub fn pose(&self, wall: usize) -> Pose {
        self.now[wall]
    }

    /// The fastest moving wall and the largest speed (m/s) of any of its points, if a wall moves.
    pub fn fastest(&self) -> Option<(usize, Real)> {
        self.moves
            .iter()
            .enumerate()
            .filter_map(|(i, m)| {
                let m = m.as_ref()?;
                let pivot = m.pose(0.0, self.drawn[i].centre()).pivot;
                Some((i, m.top_speed(self.drawn[i].reach_from(&pivot))))
            })
            .max_by(|a, b| a.1.total_cmp(&b.1))
    }

    /// The same walls with their surfaces moving as `motions` (one per wall; the box stays still).
    pub fn with_motions(mut self, motions: Vec<SurfaceMotion>) -> Self {
        assert_eq!(motions.len(), self.walls.len(), "one surface motion per wall");
        self.motions = motions;
        self.motions.push(SurfaceMotion::STILL);
        self
    }

    /// Velocity (m/s) of wall `wall`'s surface near `x`, where its outward normal is `n`: a moving
    /// wall's own velocity there (its displacement over the step, divided by the step) plus the motion
    /// of its surface along it.
    fn velocity_at(&self, wall: usize, x: &Point, n: &Point) -> Point {
        if !self.is_moving(wall) || self.dt == 0.0 {
            return self.motions[wall].at(x, n);
        }
        // The scene's surface velocity turns with the wall.
        let motion = &self.motions[wall];
        let turned = SurfaceMotion { velocity: self.now[wall].turn(&motion.velocity), ..*motion };
        let surface = turned.at(x, n);
        let carried = (self.next[wall].place(&self.now[wall].unplace(x)) - x) / self.dt;
        // The surface's own motion runs along the wall (a scene's `velocity` acts by its part along it).
        carried + (surface - n * n.dot(&surface))
    }

    /// Index of the domain box among the walls.
    pub fn box_index(&self) -> usize {
        self.walls.len()
    }
}

impl WallShape {
    /// The centre a wall turns about unless its motion names a pivot: a circle's centre, a polygon's
    /// vertex mean.
    pub fn centre(&self) -> Point {
        match self {
            WallShape::Polygon(p) | WallShape::Obstacle(p) => {
                p.vertices.iter().sum::<Point>() / p.vertices.len() as Real
            }
            WallShape::Circle(c, _) => c.center,
            WallShape::Stroke(s) => s.vertices.iter().sum::<Point>() / s.vertices.len() as Real,
        }
    }

    /// The shape in `pose`.
    fn placed(&self, pose: &Pose) -> Self {
        match self {
            WallShape::Polygon(p) => {
                WallShape::Polygon(Polygon::new(p.vertices.iter().map(|v| pose.place(v)).collect()))
            }
            WallShape::Obstacle(p) => {
                WallShape::Obstacle(Polygon::new(p.vertices.iter().map(|v| pose.place(v)).collect()))
            }
            WallShape::Circle(c, side) => {
                WallShape::Circle(Circle { center: pose.place(&c.center), radius: c.radius }, *side)
            }
            WallShape::Stroke(s) => {
                WallShape::Stroke(Stroke { vertices: s.vertices.iter().map(|v| pose.place(v)).collect(), half: s.half })
            }
        }
    }

    /// The farthest distance (m) of the shape from `pivot`.
    pub fn reach_from(&self, pivot: &Point) -> Real {
        match self {
            WallShape::Polygon(p) | WallShape::Obstacle(p) => {
                p.vertices.iter().map(|v| (v - pivot).norm()).fold(0.0, Real::max)
            }
            WallShape::Circle(c, _) => (c.center - pivot).norm() + c.radius,
            WallShape::Stroke(s) => s.vertices.iter().map(|v| (v - pivot).norm()).fold(0.0, Real::max) + s.half,
        }
    }
}

impl Walls2 {
    /// The polygon walls with their indices and whether the material is outside them (an obstacle),
    /// the domain box last.
    fn polygons(&self) -> impl Iterator<Item = (usize, &Polygon, bool)> {
        self.walls
            .iter()
            .enumerate()
            .filter_map(|(i, w)| match w {
                WallShape::Polygon(p) => Some((i, p, false)),
                WallShape::Obstacle(p) => Some((i, p, true)),
                WallShape::Circle(..) | WallShape::Stroke(_) => None,
            })
            .chain(std::iter::once((self.box_index(), &self.domain_box, false)))
    }

    /// Boundary grid points at spacing ≤ `h` (m) along every wall: polygon vertices (two
    /// normals) plus the points that split each edge into ⌈len/h⌉ equal parts, and
    /// ⌈2πr/h⌉ points around each circle. Only points on the boundary of the material
    /// region are kept (e.g. the domain box is dropped where a polygon lies inside it).
    fn sample_points(&self, h: Real) -> Vec<BoundaryPoint<2>> {
        let mut out = Vec::new();
        for (wall, poly, obstacle) in self.polygons() {
            let n = poly.vertices.len();
            // Into the wall: out of a container, into an obstacle.
            let into = if obstacle { -1.0 } else { 1.0 };
            let normal = |i: usize| {
                let e = poly.vertices[(i + 1) % n] - poly.vertices[i];
                Point::new(e.y, -e.x).normalize() * into
            };
            for i in 0..n {
                let (a, b) = (poly.vertices[i], poly.vertices[(i + 1) % n]);
                let (before, after) = (normal((i + n - 1) % n), normal(i));
                out.push(BoundaryPoint::new(a, before, after, wall));
                let parts = ((b - a).norm() / h).ceil().max(1.0) as usize;
                for k in 1..parts {
                    out.push(BoundaryPoint::new(a + (b - a) * (k as Real / parts as Real), after, after, wall));
                }
            }
        }
        for (wall, w) in self.walls.iter().enumerate() {
            if let WallShape::Stroke(s) = w {
                out.extend(s.surface(h).into_iter().map(|(x, n)| BoundaryPoint::new(x, -n, -n, wall)));
            }
            if let WallShape::Circle(c, side) = w {
                let parts = (2.0 * crate::math::PI * c.radius / h).ceil().max(8.0) as usize;
                for k in 0..parts {
                    let t = 2.0 * crate::math::PI * k as Real / parts as Real;
                    let radial = Point::new(t.cos(), t.sin());
                    let n = if *side == Side::Outside { -radial } else { radial };
                    out.push(BoundaryPoint::new(c.center + radial * c.radius, n, n, wall));
                }
            }
        }
        // A sampled point lies on its wall up to the rounding of its coordinates: in f32 that is
        // ~1e-7 of the domain size, far above 1e-9 h (which dropped half the points in f32).
        let extent = self.domain_box.vertices[2];
        let tolerance = (1e-9 * h).max(16.0 * Real::EPSILON * extent.x.max(extent.y));
        out.retain(|p| self.distance(&p.x).distance.abs() <= tolerance);
        out
    }
}

impl Region<2> for Walls2 {
    /// The domain box's, the obstacles' and the circles' parts multiply, and the containers' union takes
    /// `1 − Π(1 − f)` (each wall's cut taken as independent of the others').
    fn support_fraction(&self, x: &Point, h: Real) -> Real {
        let mut inside = self.domain_box.support_inside(x, h);
        let (mut containers, mut outside_all) = (false, 1.0);
        for wall in &self.walls {
            match wall {
                WallShape::Polygon(p) => {
                    containers = true;
                    outside_all *= 1.0 - p.support_inside(x, h);
                }
                WallShape::Obstacle(p) => inside *= 1.0 - p.support_inside(x, h),
                WallShape::Stroke(s) => inside *= bspline_integral(s.signed_distance(x).0 / h),
                WallShape::Circle(c, side) => {
                    let d = c.signed_distance(x).0;
                    inside *= bspline_integral(match side {
                        Side::Inside => -d / h,
                        Side::Outside => d / h,
                    });
                }
            }
        }
        if containers {
            inside *= 1.0 - outside_all;
        }
        inside
    }

    fn outlines(&self) -> Vec<Vec<Point>> {
        self.walls
            .iter()
            .map(|w| match w {
                WallShape::Polygon(p) | WallShape::Obstacle(p) => p.vertices.clone(),
                WallShape::Circle(c, _) => (0..64)
                    .map(|k| {
                        let t = 2.0 * crate::math::PI * k as Real / 64.0;
                        c.center + Point::new(t.cos(), t.sin()) * c.radius
                    })
                    .collect(),
                // Arcs in steps of at most π/16.
                WallShape::Stroke(s) => {
                    s.surface(s.half * crate::math::PI / 16.0).into_iter().map(|(x, _)| x).collect()
                }
            })
            .collect()
    }

    fn is_moving(&self, wall: usize) -> bool {
        Walls2::is_moving(self, wall)
    }

    fn placement(&self, wall: usize) -> Option<Placement<2>> {
        if !self.is_moving(wall) {
            return None;
        }
        let (now, next) = (self.now[wall], self.next[wall]);
        Some(Placement {
            pivot: now.pivot,
            offset: [now.offset, next.offset],
            turn: [[0.0, 0.0, now.angle], [0.0, 0.0, next.angle]],
        })
    }

    fn surface_velocity(&self, wall: usize, x: &Point, n: &Point) -> Point {
        self.velocity_at(wall, x, n)
    }

    fn boundary_points(&self, spacing: Real) -> Vec<BoundaryPoint<2>> {
        let mut points = self.sample_points(spacing);
        for p in &mut points {
            p.velocity = self.velocity_at(p.wall, &p.x, &p.normals[0]);
        }
        points
    }

    fn moves(&self) -> bool {
        self.moves.iter().any(Option::is_some) || self.set.iter().any(Option::is_some)
    }

    fn num_walls(&self) -> usize {
        self.walls.len()
    }

    fn pose_change(&self, wall: usize, pose: &WallPose<2>) -> (Real, Real) {
        let (now, reach) = (self.now[wall], self.reach(wall));
        let new = pose.pose(pose.time, self.pivot(wall));
        ((new.offset - now.offset).norm() + (new.angle - now.angle).abs() * reach, pose.top_speed(reach))
    }

    fn set_poses(&mut self, poses: &[(usize, WallPose<2>)]) {
        self.set.fill(None);
        for &(wall, pose) in poses {
            self.set[wall] = Some(pose);
        }
    }

    fn sweep(&self) -> Real {
        self.sweep
    }

    fn set_time(&mut self, t: Real, dt: Real) {
        self.dt = dt;
        self.sweep = 0.0;
        for i in 0..self.walls.len() {
            let before = self.now[i];
            let centre = self.drawn[i].centre();
            let poses = match (&self.set[i], &self.moves[i]) {
                (Some(set), _) => Some((set.pose(t, self.pivot(i)), set.pose(t + dt, self.pivot(i)))),
                (None, Some(motion)) => Some((motion.pose(t, centre), motion.pose(t + dt, centre))),
                (None, None) => {
                    // A wall whose set pose was taken back (a restored state) returns to its drawing.
                    if self.walls[i] != self.drawn[i] {
                        self.walls[i] = self.drawn[i].clone();
                        (self.now[i], self.next[i]) = (Pose::still(centre), Pose::still(centre));
                    }
                    None
                }
            };
            if let Some(poses) = poses {
                (self.now[i], self.next[i]) = poses;
                self.walls[i] = self.drawn[i].placed(&self.now[i]);
            }
            // About the same pivot, a point at r from it moves by at most |Δoffset| + |Δangle| r.
            let after = self.now[i];
            if after.pivot != before.pivot {
                self.sweep = Real::INFINITY;
            } else if after != before {
                let turn = (after.angle - before.angle).abs() * self.reach(i);
                let moved = (after.offset - before.offset).norm() + turn;
                // A pose gone NaN bounds nothing (`max` would drop the NaN): as in 3D, infinite.
                self.sweep = if moved.is_nan() { Real::INFINITY } else { self.sweep.max(moved) };
            }
            if let WallShape::Circle(c, _) = &self.walls[i] {
                self.motions[i].center = Some(c.center);
            }
        }
    }

    fn distance(&self, x: &Vector<2>) -> WallDistance<2> {
        // Intersection of constraints: the largest signed distance wins.
        let (d, n) = self.domain_box.signed_distance(x);
        let mut out = WallDistance { distance: d, normal: n, wall: self.box_index() };
        // Union of polygon containers: the smallest signed distance among them.
        let mut union: Option<WallDistance<2>> = None;
        for (i, w) in self.walls.iter().enumerate() {
            match w {
                WallShape::Polygon(p) => {
                    let (d, n) = p.signed_distance(x);
                    if union.is_none_or(|u| d < u.distance) {
                        union = Some(WallDistance { distance: d, normal: n, wall: i });
                    }
                }
                WallShape::Obstacle(p) => {
                    let (d, n) = p.signed_distance(x);
                    if -d > out.distance {
                        out = WallDistance { distance: -d, normal: -n, wall: i };
                    }
                }
                WallShape::Stroke(s) => {
                    let (d, n) = s.signed_distance(x);
                    if -d > out.distance {
                        out = WallDistance { distance: -d, normal: -n, wall: i };
                    }
                }
                WallShape::Circle(c, side) => {
                    let (d, n) = c.signed_distance(x);
                    let (d, n) = match side {
                        Side::Inside => (d, n),
                        Side::Outside => (-d, -n),
                    };
                    if d > out.distance {
                        out = WallDistance { distance: d, normal: n, wall: i };
                    }
                }
            }
        }
        match union {
            Some(u) if u.distance > out.distance => u,
            _ => out,
        }
    }

    fn wall_feet(&self, x: &Point, reach: Real) -> WallFeet<2> {
        let mut feet = WallFeet::default();
        // A face point counts only where it bounds the material region (a polygon edge inside
        // another polygon, or the domain box beyond a container, does not).
        let tolerance = Real::EPSILON.sqrt() * reach;
        let mut add = |q: Point, normal: Point, wall: usize, curvature: Real| {
            if self.distance(&q).distance.abs() <= tolerance {
                let velocity = self.velocity_at(wall, &q, &normal);
                let centre_velocity = if curvature > 0.0 && self.is_moving(wall) && self.dt > 0.0 {
                    let c = q - normal / curvature;
                    (self.next[wall].place(&self.now[wall].unplace(&c)) - c) / self.dt
                } else {
                    Point::zeros()
                };
                // The turn of the wall over the step (exactly none for a still or only translated wall).
                let turn = if self.is_moving(wall) { self.next[wall].angle - self.now[wall].angle } else { 0.0 };
                let normal_next = if turn != 0.0 {
                    Pose { pivot: Point::zeros(), offset: Point::zeros(), angle: turn }.turn(&normal)
                } else {
                    normal
                };
                let foot = WallFoot {
                    x: q,
                    normal,
                    wall,
                    velocity,
                    curvature,
                    centre_velocity,
                    normal_next,
                    depth: Real::NEG_INFINITY,
                };
                feet.push(foot, (x - q).norm(), tolerance);
            }
        };
        for (wall, poly, obstacle) in self.polygons() {
            let n = poly.vertices.len();
            let into = if obstacle { -1.0 } else { 1.0 };
            // Where x's perpendicular lands on each edge, as a fraction of its length.
            let along = |k: usize| {
                let (a, b) = (poly.vertices[k], poly.vertices[(k + 1) % n]);
                (x - a).dot(&(b - a)) / (b - a).norm_squared()
            };
            for k in 0..n {
                let (a, b) = (poly.vertices[k], poly.vertices[(k + 1) % n]);
                let e = b - a;
                let t = along(k);
                if t > 0.0 && t < 1.0 {
                    let q = a + e * t;
                    if (x - q).norm() < reach {
                        add(q, Point::new(e.y, -e.x).normalize() * into, wall, 0.0);
                    }
                }
                // x past the end of the edge before a and before the start of this one sees the
                // corner a itself: at a reflex corner (the polygon turns clockwise there) from inside,
                // the wall lies towards a; at a convex one x has left the region, and the wall lies
                // back towards the material (so a particle that escaped there goes no farther).
                let before = a - poly.vertices[(k + n - 1) % n];
                let d = (a - x).norm();
                if t <= 0.0 && along((k + n - 1) % n) >= 1.0 && d > 0.0 && d < reach {
                    // Seen from the material, an obstacle's corners turn the other way.
                    let reflex = (before.perp(&e) < 0.0) != obstacle;
                    let normal = if reflex { (a - x) / d } else { (x - a) / d };
                    add(a, normal, wall, 0.0);
                }
            }
        }
        for (wall, w) in self.walls.iter().enumerate() {
            if let WallShape::Stroke(s) = w {
                // On each side face where x's perpendicular lands on its segment, and on the round end or
                // joint at each vertex x lies beyond both segments of (curving away: curvature 0).
                let m = s.vertices.len();
                let mut foot = |q: Point| {
                    let r = x - q;
                    let d = r.norm();
                    if d > 0.0 && (d - s.half).abs() < reach {
                        let out = r / d;
                        add(q + out * s.half, -out, wall, 0.0);
                    }
                };
                for k in 0..m - 1 {
                    let t = s.along(k, x);
                    if t > 0.0 && t < 1.0 {
                        foot(s.vertices[k] + (s.vertices[k + 1] - s.vertices[k]) * t);
                    }
                }
                for j in 0..m {
                    let past_before = j == 0 || s.along(j - 1, x) >= 1.0;
                    let past_after = j == m - 1 || s.along(j, x) <= 0.0;
                    if past_before && past_after {
                        foot(s.vertices[j]);
                    }
                }
            }
            if let WallShape::Circle(c, side) = w {
                let r = x - c.center;
                let norm = r.norm();
                if norm > 0.0 && (norm - c.radius).abs() < reach {
                    let radial = r / norm;
                    let (normal, curvature) =
                        if *side == Side::Outside { (-radial, 0.0) } else { (radial, 1.0 / c.radius) };
                    add(c.center + radial * c.radius, normal, wall, curvature);
                }
            }
        }
        feet
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square() -> Polygon {
        Polygon::new(vec![Point::new(0.0, 0.0), Point::new(1.0, 0.0), Point::new(1.0, 1.0), Point::new(0.0, 1.0)])
    }

    #[test]
    fn polygon_area_orientation_and_distance() {
        let s = square();
        assert!((s.signed_area() - 1.0).abs() < 1e-15);
        let (d, n) = s.signed_distance(&Point::new(0.5, -0.25));
        assert!((d - 0.25).abs() < 1e-15 && (n - Point::new(0.0, -1.0)).norm() < 1e-15);
        let (d, n) = s.signed_distance(&Point::new(0.9, 0.5));
        assert!((d + 0.1).abs() < 1e-12 && (n - Point::new(1.0, 0.0)).norm() < 1e-12);
        let (d, n) = s.signed_distance(&Point::new(1.0, 0.3));
        assert!(d.abs() < 1e-15 && (n - Point::new(1.0, 0.0)).norm() < 1e-15);
    }

    /// The paper's container (shared/spec/paper-scenes.md): 4 vertices plus ⌈len/h⌉ − 1 points per
    /// edge, none of the domain box (it lies outside the polygon), each at spacing ≤ h.
    #[test]
    fn boundary_points_of_the_paper_container() {
        let h = 1.0 / 80.0;
        let poly = Polygon::new(vec![
            Point::new(0.047, 0.5),
            Point::new(0.953, 0.047),
            Point::new(0.953, 0.953),
            Point::new(0.047, 0.953),
        ]);
        let expected: usize = poly.edges().map(|(a, b)| ((b - a).norm() / h).ceil() as usize).sum();
        let walls = Walls2::new(vec![WallShape::Polygon(poly)], Point::new(1.0, 1.0));
        let pts = walls.boundary_points(h);
        assert_eq!(pts.len(), expected);
        assert!(pts.iter().all(|p| p.wall == 0));
        let corners = pts.iter().filter(|p| p.normals[0] != p.normals[1]).count();
        assert_eq!(corners, 4);
        for w in pts.windows(2) {
            if w[0].wall == w[1].wall {
                assert!((w[1].x - w[0].x).norm() <= h * (1.0 + 1e-12));
            }
        }
    }

    /// A belt loop runs counter-clockwise along its polygon (+x on the floor, −x on the ceiling);
    /// a spinning circle runs counter-clockwise around its centre.
    #[test]
    fn tangential_speed_runs_counter_clockwise() {
        let belt = SurfaceMotion { velocity: Point::zeros(), tangential_speed: 2.0, center: None };
        assert_eq!(belt.at(&Point::new(0.5, 0.0), &Point::new(0.0, -1.0)), Point::new(2.0, 0.0));
        assert_eq!(belt.at(&Point::new(0.5, 1.0), &Point::new(0.0, 1.0)), Point::new(-2.0, 0.0));
        let spin =
            SurfaceMotion { velocity: Point::zeros(), tangential_speed: 3.0, center: Some(Point::new(0.5, 0.5)) };
        let v = spin.at(&Point::new(0.7, 0.5), &Point::new(-1.0, 0.0));
        assert!((v - Point::new(0.0, 3.0)).norm() < 1e-15);
    }

    /// The feet of a particle: one per face in reach with the face's outward normal; a polygon edge on
    /// the domain box counts once; an edge inside another polygon of the union is no wall; a reflex
    /// corner seen past both faces is a foot, as is a convex corner seen by a particle that left.
    #[test]
    fn wall_feet_of_polygons() {
        let reach = 0.15;
        // A container whose floor lies on the domain box's bottom edge.
        let walls = Walls2::new(vec![WallShape::Polygon(square())], Point::new(1.0, 1.0));
        let feet = walls.wall_feet(&Point::new(0.5, 0.1), reach);
        assert_eq!(feet.len(), 1);
        let f = feet.iter().next().unwrap();
        assert!((f.x - Point::new(0.5, 0.0)).norm() < 1e-15 && (f.normal - Point::new(0.0, -1.0)).norm() < 1e-15);
        assert_eq!(walls.wall_feet(&Point::new(0.1, 0.05), reach).len(), 2); // the corner: floor and left wall
        assert!(walls.wall_feet(&Point::new(0.5, 0.5), reach).is_empty());
        // An L of two overlapping rectangles: A's top edge within B is no wall.
        let a =
            Polygon::new(vec![Point::new(0.1, 0.1), Point::new(0.9, 0.1), Point::new(0.9, 0.4), Point::new(0.1, 0.4)]);
        let b =
            Polygon::new(vec![Point::new(0.1, 0.1), Point::new(0.4, 0.1), Point::new(0.4, 0.9), Point::new(0.1, 0.9)]);
        let union = Walls2::new(vec![WallShape::Polygon(a), WallShape::Polygon(b)], Point::new(1.0, 1.0));
        let feet = union.wall_feet(&Point::new(0.25, 0.35), reach);
        assert!(feet.iter().all(|f| (f.x.y - 0.4).abs() > 1e-9), "A's top edge inside B is no wall");
        // A reflex corner of one polygon (an L, counter-clockwise), seen from inside past both faces.
        let l = Polygon::new(vec![
            Point::new(0.1, 0.1),
            Point::new(0.9, 0.1),
            Point::new(0.9, 0.4),
            Point::new(0.4, 0.4),
            Point::new(0.4, 0.9),
            Point::new(0.1, 0.9),
        ]);
        let walls = Walls2::new(vec![WallShape::Polygon(l)], Point::new(1.0, 1.0));
        let x = Point::new(0.35, 0.35);
        let feet = walls.wall_feet(&x, reach);
        let corner = feet.iter().find(|f| (f.x - Point::new(0.4, 0.4)).norm() < 1e-15).expect("the reflex corner");
        assert!((corner.normal - (Point::new(0.4, 0.4) - x).normalize()).norm() < 1e-12);
        // A particle that left the unit square past its convex corner (1, 1) faces back towards it.
        let walls = Walls2::new(vec![WallShape::Polygon(square())], Point::new(2.0, 2.0));
        let out = Point::new(1.05, 1.05);
        let feet = walls.wall_feet(&out, reach);
        assert_eq!(feet.len(), 1);
        let f = feet.iter().next().unwrap();
        assert!((f.normal - (out - Point::new(1.0, 1.0)).normalize()).norm() < 1e-12);
    }

    /// Circles: an obstacle's foot faces its centre and is flat for the fit (curvature 0: a straight
    /// step moves away from it); a container's faces outward with curvature 1/R.
    #[test]
    fn wall_feet_of_circles() {
        let c = Circle { center: Point::new(0.5, 0.5), radius: 0.2 };
        let obstacle = Walls2::new(vec![WallShape::Circle(c.clone(), Side::Outside)], Point::new(1.0, 1.0));
        let f = *obstacle.wall_feet(&Point::new(0.8, 0.5), 0.15).iter().next().unwrap();
        assert!((f.x - Point::new(0.7, 0.5)).norm() < 1e-15 && (f.normal - Point::new(-1.0, 0.0)).norm() < 1e-15);
        assert_eq!(f.curvature, 0.0);
        let container = Walls2::new(vec![WallShape::Circle(c, Side::Inside)], Point::new(1.0, 1.0));
        let f = *container.wall_feet(&Point::new(0.6, 0.5), 0.15).iter().next().unwrap();
        assert!((f.x - Point::new(0.7, 0.5)).norm() < 1e-15 && (f.normal - Point::new(1.0, 0.0)).norm() < 1e-15);
        assert!((f.curvature - 5.0).abs() < 1e-12);
    }

    /// With more faces in reach than it holds, a particle keeps the nearest ones.
    #[test]
    fn wall_feet_keep_the_nearest() {
        let mut feet = WallFeet::<2>::default();
        for k in 0..(MAX_FEET + 2) {
            let d = [0.5, 0.1, 0.4, 0.05, 0.3, 0.2][k];
            let n = Point::new((k as Real).cos(), (k as Real).sin());
            let foot = WallFoot::still(n * d, n, k);
            feet.push(foot, d, 1e-12);
        }
        let mut kept: Vec<usize> = feet.iter().map(|f| f.wall).collect();
        kept.sort_unstable();
        assert_eq!(kept, vec![1, 3, 4, 5]); // distances 0.1, 0.05, 0.3, 0.2
    }

    #[test]
    fn bow_tie_self_intersects_and_square_does_not() {
        assert_eq!(square().self_intersection(), None);
        let bow =
            Polygon::new(vec![Point::new(0.0, 0.0), Point::new(1.0, 1.0), Point::new(1.0, 0.0), Point::new(0.0, 1.0)]);
        assert!(bow.self_intersection().is_some());
    }

    #[test]
    fn region_combines_box_polygon_and_obstacle() {
        let tri = Polygon::new(vec![Point::new(0.1, 0.1), Point::new(0.9, 0.1), Point::new(0.5, 0.9)]);
        let obstacle = Circle { center: Point::new(0.5, 0.3), radius: 0.1 };
        let walls = Walls2::new(
            vec![WallShape::Polygon(tri), WallShape::Circle(obstacle, Side::Outside)],
            Point::new(1.0, 1.0),
        );
        let at_centre = walls.distance(&Point::new(0.5, 0.3));
        assert_eq!(at_centre.wall, 1);
        assert!((at_centre.distance - 0.1).abs() < 1e-15);
        let inside = walls.distance(&Point::new(0.5, 0.15));
        assert!(inside.distance < 0.0);
        let below = walls.distance(&Point::new(0.5, 0.05));
        assert_eq!(below.wall, 0);
        assert!((below.distance - 0.05).abs() < 1e-15);
        assert!((below.normal - Point::new(0.0, -1.0)).norm() < 1e-12);
        let outside_box = walls.distance(&Point::new(-0.1, 0.5));
        assert!(outside_box.distance > 0.0);
    }

    /// A square obstacle (material around it): positive distance inside it with the normal pointing
    /// into it, boundary points on its edges with normals into it (two at each corner), and from a
    /// particle off a corner, the corner as its foot with the normal towards it.
    #[test]
    fn a_polygon_obstacle_keeps_the_material_around_it() {
        let block =
            Polygon::new(vec![Point::new(0.4, 0.4), Point::new(0.6, 0.4), Point::new(0.6, 0.6), Point::new(0.4, 0.6)]);
        let walls = Walls2::new(vec![WallShape::Obstacle(block)], Point::new(1.0, 1.0));
        let inside = walls.distance(&Point::new(0.45, 0.5));
        assert_eq!(inside.wall, 0);
        assert!((inside.distance - 0.05).abs() < 1e-15 && (inside.normal - Point::new(1.0, 0.0)).norm() < 1e-12);
        let around = walls.distance(&Point::new(0.35, 0.5));
        assert!(around.distance < 0.0);
        let points: Vec<_> = walls.boundary_points(0.05).into_iter().filter(|p| p.wall == 0).collect();
        assert_eq!(points.len(), 16);
        for p in &points {
            // Into the obstacle: towards its centre.
            assert!(p.normals.iter().all(|n| n.dot(&(Point::new(0.5, 0.5) - p.x)) > 0.0), "{p:?}");
        }
        let x = Point::new(0.38, 0.38);
        let feet = walls.wall_feet(&x, 0.05);
        let corner = feet.iter().find(|f| f.wall == 0).expect("the corner is a foot");
        assert!((corner.x - Point::new(0.4, 0.4)).norm() < 1e-15);
        assert!((corner.normal - (corner.x - x).normalize()).norm() < 1e-12);
    }

    /// A moving wall's velocity at a point is its displacement over the step divided by the step: a box
    /// carried at (0.3, 0) m/s and turning at 1 rad/s about its centre moves a point 0.1 m right of the
    /// centre at (0.3, 0.1) m/s (to first order in the step); a surface velocity given on it acts along
    /// the wall only.
    #[test]
    fn a_moving_wall_carries_its_points() {
        let square =
            Polygon::new(vec![Point::new(0.3, 0.3), Point::new(0.7, 0.3), Point::new(0.7, 0.7), Point::new(0.3, 0.7)]);
        let motion = Motion::Constant { velocity: [0.3, 0.0], angular_velocity: 1.0, pivot: None };
        let push = SurfaceMotion { velocity: Point::new(0.0, 5.0), tangential_speed: 0.0, center: None };
        let mut walls = Walls2::new(vec![WallShape::Polygon(square)], Point::new(1.0, 1.0))
            .with_motions(vec![push])
            .with_moves(vec![Some(motion)]);
        walls.set_time(0.0, 1e-6);
        let n = Point::new(0.0, 1.0); // the top face, at y = 0.7
        let v = walls.velocity_at(0, &Point::new(0.6, 0.7), &n);
        // Carried: (0.3, 0) + 1 rad/s × (0.1, 0.2) = (0.3 − 0.2, 0.1); the push (0, 5) is normal to the face.
        assert!((v - Point::new(0.1, 0.1)).norm() < 1e-5, "{v}");
        assert!(walls.moves() && walls.is_moving(0) && !walls.is_moving(1));
    }

    /// A bent plate (an L of two 0.4 m segments, 0.06 m wide) is an obstacle: the distance is the
    /// distance to its centreline less the half width, its boundary points lie on its surface at most h
    /// apart (on the outer arc of the bend too) and face into it, and a particle beside it has its foot
    /// on the face it looks at.
    #[test]
    fn a_polyline_wall_is_a_stroke_with_round_ends() {
        let plate =
            Stroke { vertices: vec![Point::new(0.3, 0.3), Point::new(0.7, 0.3), Point::new(0.7, 0.7)], half: 0.03 };
        let walls = Walls2::new(vec![WallShape::Stroke(plate.clone())], Point::new(1.0, 1.0));
        let d = walls.distance(&Point::new(0.5, 0.2));
        assert!((d.distance + 0.07).abs() < 1e-12 && (d.normal - Point::new(0.0, 1.0)).norm() < 1e-12);
        assert!((walls.distance(&Point::new(0.5, 0.31)).distance - 0.02).abs() < 1e-12, "inside the plate");
        // Beyond the round end at (0.3, 0.3).
        assert!((walls.distance(&Point::new(0.2, 0.3)).distance + 0.07).abs() < 1e-12);
        let h = 0.01;
        let points: Vec<_> = walls.sample_points(h).into_iter().filter(|p| p.wall == 0).collect();
        for p in &points {
            assert!(walls.distance(&p.x).distance.abs() < 1e-9, "{:?} off the surface", p.x);
            // (At the inner corner of the bend, where the two faces meet, either face's normal will do.)
            let (_, out) = plate.signed_distance(&p.x);
            let inner_corner = (p.x - Point::new(0.67, 0.33)).norm() < 1e-9;
            assert!(inner_corner || (p.normals[0] + out).norm() < 1e-9, "normal into the wall at {:?}", p.x);
        }
        // Walked around, consecutive points are at most h apart (the bend's inner corner aside, where the
        // offset lines cross: 2 gaps).
        let gaps = points.windows(2).filter(|w| (w[1].x - w[0].x).norm() > h * (1.0 + 1e-9)).count();
        assert!(gaps <= 2, "{gaps} gaps");
        // Length of the surface: 2 (0.4 + 0.4) sides less the inner corner's overlap, one circle of ends,
        // a quarter circle at the bend: about 1.6 + 2π 0.03 + π/2 0.03 − 2·0.06 ≈ 1.67 m, so ≥ 167 points.
        assert!(points.len() >= 167, "{}", points.len());
        let feet = walls.wall_feet(&Point::new(0.5, 0.4), 0.1);
        let foot = feet.iter().next().expect("a foot on the upper face");
        assert!(
            (foot.x - Point::new(0.5, 0.33)).norm() < 1e-12 && (foot.normal - Point::new(0.0, -1.0)).norm() < 1e-12
        );
        // Beyond the outer corner of the bend: the foot is on its arc.
        let feet = walls.wall_feet(&Point::new(0.75, 0.25), 0.1);
        let expected = Point::new(0.7, 0.3) + Point::new(1.0, -1.0).normalize() * 0.03;
        assert!(feet.iter().any(|f| (f.x - expected).norm() < 1e-12), "the bend's arc");
    }
}
