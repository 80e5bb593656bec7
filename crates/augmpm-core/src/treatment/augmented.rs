//! The augmented grid of Toyota & Umetani 2024: boundary grid points sampled
//! along the walls join the regular nodes that lie farther than δ inside the
//! material, and every particle solves its own MLS system (eq. (3)–(6)) over
//! the included nodes and boundary points in its B-spline support.

use crate::geometry::Region;
use crate::grid::{GridLayout, OutOfGrid, GHOST};
use crate::kernel::{weight, MlsInverse, MlsKind, Moments, Stencil};
use crate::math::{floor_i64, keep_spin, resize_with_margin, DimOps, Matrix, Real, Vector};
use crate::wall::{BoundaryPoint, WallContact, WallImpulses};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// How mass and momentum move between particles and the augmented grid (`augmented.transfer`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum AugmentedTransfer {
    /// Energy-stable: P2G with the particle's normalised B-spline weights `w / Σw` (the transpose
    /// of the G2P fit), G2P fitted to the wall value at the particle's foot on each wall in reach
    /// ([`crate::treatment::wall_fit`]); no velocity clamp, no mass floor.
    #[schemars(description = "energy-stable: the transfers are each other's transpose and G2P meets the wall \
                              condition at the particle's foot on each wall (docs/stable_transfer.md)")]
    #[default]
    Stable,
    /// The paper's: P2G with the MLS shape function φ (eq. (6)), G2P the fit of eq. (4), with
    /// augmpm's two safety nets, the low-mass floor and the hold of particles past a wall.
    #[schemars(description = "the paper's: P2G with the MLS shape function φ (eq. (6)), G2P the fit of eq. (4)")]
    Paper,
}

/// Most boundary points remembered per particle between the stages of a step;
/// a particle that sees more (dense sampling, sharp corners) looks them up again.
pub const MAX_NEAR: usize = 12;

/// The boundary points in a particle's support, found once per step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NearPoints {
    /// Number of entries of `idx` in use; `u8::MAX` when they did not fit.
    len: u8,
    idx: [u32; MAX_NEAR],
}

impl NearPoints {
    pub const NONE: Self = Self { len: 0, idx: [0; MAX_NEAR] };
    const OVERFLOW: u8 = u8::MAX;

    fn push(&mut self, b: u32) {
        if (self.len as usize) < MAX_NEAR {
            self.idx[self.len as usize] = b;
            self.len += 1;
        } else {
            self.len = Self::OVERFLOW;
        }
    }
}

/// The stable transfer's reweighting of a particle's grid points, `w → s·w·exp(η·d)` with `d = x_i − x_p`:
/// the local maximum-entropy weights of Arroyo & Ortiz (2006) with the B-spline weight as prior. η is
/// chosen so that the weights' first moment vanishes, `Σ w exp(η·d) d = 0`, as the whole B-spline stencil's
/// does; s keeps their sum `Σw`. They are positive (the paper's φ has the same zero first moment and is
/// linear in d, and turns negative), so the particle's momentum and angular momentum on the grid are those
/// at its own position, x_p × m v_p plus the affine part, not at the centroid of its grid points.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tilt<const D: usize> {
    eta: Vector<D>,
    scale: Real,
}

impl<const D: usize> Tilt<D> {
    /// No reweighting (the paper's transfer, and particles whose stencil is whole).
    pub fn none() -> Self {
        Self { eta: Vector::<D>::zeros(), scale: 1.0 }
    }

    /// Per axis a and stencil offset j, the factor `exp(η_a d_aj)` of the reweighting of the nodes of the
    /// stencil `s` (spacing `h`, m): a node's `exp(η·d)` is the product of its three (in 3D, 9 exponentials
    /// for 27 nodes). `None` without reweighting.
    #[inline]
    fn node_factors(&self, s: &Stencil<D>, h: Real) -> Option<[[Real; 3]; D]> {
        (self.eta != Vector::<D>::zeros())
            .then(|| std::array::from_fn(|a| [0, 1, 2].map(|j| (self.eta[a] * ((j as Real - s.fx[a]) * h)).exp())))
    }

    /// The reweighted weight of a grid point with B-spline weight `w` at `d = x_i − x_p`.
    #[inline]
    pub fn weight(&self, w: Real, d: &Vector<D>) -> Real {
        if self.eta == Vector::<D>::zeros() {
            w * self.scale
        } else {
            w * self.scale * self.eta.dot(d).exp()
        }
    }
}

/// Most Newton iterations for the tilt's η; from η = 0 it converges in 3–4 (at most 6 over the particles of
/// the stable-transfer property tests), unless a limit below stops it.
const TILT_ITERATIONS: usize = 16;

/// Largest |η| h: a particle closer to a wall than its grid points reach around it (its position on
/// the edge of their convex hull) would need η → ∞; the cap bounds the weights' ratios, leaving a small
/// first moment.
const TILT_MAX: Real = 4.0;

/// Least spread of the reweighted points, in h² (the smallest eigenvalue of their covariance; 1/4 on
/// a whole stencil), unless the B-spline weights' own is smaller. Concentrated on a wall, the weights
/// spread little normal to it, and the MLS gradient, with the stress it carries, stiffens as the
/// inverse of that spread: at 1/25 it is at most 6.25 times the regular grid's. (At 1/50 the viscous
/// hydrostatic column with the grid density, run at 0.4 of its stable step, blew up; at 1/33 it ran.)
const TILT_SPREAD: Real = 0.04;

/// Most grid points of one particle whose weights the tilt centres: its whole stencil and 100 boundary
/// points (more than [`MAX_NEAR`], which only bounds what the table remembers: in 3D a particle near a
/// wall's edge or corner sees 20–40). A particle that sees more keeps its B-spline weights.
const MAX_POINTS: usize = crate::math::stencil_len(3) + 100;

/// The [`Tilt`] of a particle whose grid points have B-spline weights and offsets `points` (m), summing
/// to `total`, and the moments (eq. (5)) of the reweighted points: η minimises the convex
/// F(η) = log Σ w exp(η·d), whose gradient is the reweighted first moment and whose Hessian its
/// covariance, by Newton's method in units of h (`inv_h` = 1/h), with steps of at most 1/h, within the
/// limits [`TILT_MAX`] and [`TILT_SPREAD`]. The last iterate's moments are the MLS system's.
///
/// The first points are nodes of the particle's stencil at the `offsets` given, the particle at `fx`
/// (cells) from its lowest node; in 3D their exponentials are products of per-axis factors (9 for 27
/// nodes, equal to rounding).
fn centred_tilt<const D: usize, Ops: DimOps<D>>(
    points: &[(Real, Vector<D>)],
    offsets: &[[usize; D]],
    fx: &Vector<D>,
    inv_h: Real,
    total: Real,
) -> (Tilt<D>, Moments<D>) {
    let tolerance = 100.0 * Real::EPSILON;
    // The reweighted moments in units of h, their mean and covariance.
    let moments = |mu: &Vector<D>| {
        let mut m = Moments::new();
        let tilted = *mu != Vector::<D>::zeros();
        let factors: Option<[[Real; 3]; D]> =
            (D == 3 && tilted).then(|| std::array::from_fn(|a| [0, 1, 2].map(|j| (mu[a] * (j as Real - fx[a])).exp())));
        for (k, (w, d)) in points.iter().enumerate() {
            let e = d * inv_h;
            let w = match (factors, offsets.get(k)) {
                (Some(f), Some(o)) => w * (0..D).map(|a| f[a][o[a]]).product::<Real>(),
                _ if tilted => w * mu.dot(&e).exp(),
                _ => *w,
            };
            m.add(w, &e);
        }
        let mean = m.b / m.a;
        (m, mean, m.c / m.a - mean * mean.transpose())
    };
    let mut mu = Vector::<D>::zeros();
    let (mut m, mut mean, mut cov) = moments(&mu);
    if m.a <= 0.0 {
        return (Tilt::none(), Moments::new());
    }
    // The weights' spread normal to a wall shrinks as they concentrate on it, and the MLS gradient
    // (and the stress it carries) stiffens as its inverse: the tilt keeps it above the floor.
    let floor = Ops::min_sym_eigenvalue(&cov).min(TILT_SPREAD);
    for _ in 0..TILT_ITERATIONS {
        if mean.norm() <= tolerance {
            break;
        }
        let Some(inverse) = Ops::inverse(&cov) else { break };
        let mut step = -(inverse * mean);
        step /= step.norm().max(1.0);
        let (mut accepted, mut capped) = (false, false);
        for _ in 0..4 {
            let mut trial = mu + step;
            capped = trial.norm() > TILT_MAX;
            if capped {
                trial *= TILT_MAX / trial.norm();
            }
            let (m_t, mean_t, cov_t) = moments(&trial);
            if Ops::at_least(&cov_t, floor) {
                (mu, m, mean, cov, accepted) = (trial, m_t, mean_t, cov_t, true);
                break;
            }
            step *= 0.5;
        }
        if !accepted || capped {
            break;
        }
    }
    let scale = total / m.a;
    let h = 1.0 / inv_h;
    let metres = Moments { a: total, b: m.b * (scale * h), c: m.c * (scale * h * h) };
    (Tilt { eta: mu * inv_h, scale }, metres)
}

/// Regular nodes kept for interpolation, the boundary points, a per-cell
/// index of the boundary points, and which stencils can use the closed form.
#[derive(Clone, Debug)]
pub struct AugmentedGrid<const D: usize> {
    pub points: Vec<BoundaryPoint<D>>,
    /// Per regular node: inside the material region and farther than δ from every wall.
    pub included: Vec<bool>,
    /// Per stencil base node: all 3^D nodes included and no boundary point can be in the support.
    pub closed_form: Vec<bool>,
    /// Boundary points by cell (cell = node at its lower corner): `cell_points[cell_start[c]..cell_start[c + 1]]`.
    cell_start: Vec<u32>,
    cell_points: Vec<u32>,
    /// Condition and friction of each wall.
    pub walls: Vec<WallContact>,
    /// Exclusion distance δ (m).
    pub delta: Real,
    /// Largest spacing of the boundary points (m).
    pub spacing: Real,
    /// Per cell (cell = node at its lower corner): the whole cell lies inside the material region.
    cell_inside: Vec<bool>,
    /// How particles and grid exchange mass and momentum.
    pub transfer: AugmentedTransfer,
    /// What a grid whose walls move keeps between follows (`None` until the first).
    follow: Option<Follow>,
}

/// What [`AugmentedGrid::follow`] keeps between steps, so that it looks only at what the walls swept.
#[derive(Clone, Debug)]
struct Follow {
    /// How far (m) the walls may have moved in all, the sum of every follow's `Region::sweep`.
    swept: Real,
    /// Per node, the `swept` at which its classification may change and it must be looked at again.
    due: Vec<Real>,
    /// Per stencil base node, how many boundary points reach its support.
    reached: Vec<u32>,
}

/// The cell (the node at its lower corner) that holds `x`, if it is in the grid.
fn cell_of<const D: usize>(layout: &GridLayout<D>, x: &Vector<D>) -> Option<usize> {
    let inv_h = 1.0 / layout.h;
    layout.node_index(&std::array::from_fn(|k| (x[k] * inv_h).floor() as i64))
}

/// Calls `f` with each stencil base node whose particles' support can hold a boundary point at `x`: a
/// particle with stencil base b lies in [b + 1/2, b + 3/2) h per axis, so its support is inside
/// ((b − 1) h, (b + 3) h), and the point reaches the bases in (x/h − 3, x/h + 1).
fn reach_bases<const D: usize>(layout: &GridLayout<D>, x: &Vector<D>, mut f: impl FnMut(usize)) {
    let inv_h = 1.0 / layout.h;
    let lo: [i64; D] = std::array::from_fn(|k| (x[k] * inv_h - 3.0).floor() as i64);
    for k in 0..4usize.pow(D as u32) {
        let mut c = lo;
        let mut r = k;
        for ck in c.iter_mut() {
            *ck += (r % 4) as i64 + 1;
            r /= 4;
        }
        // Bases lo+1 ..= lo+4 cover the open interval (x/h − 3, x/h + 1).
        if let Some(i) = layout.node_index(&c) {
            f(i);
        }
    }
}

impl<const D: usize> AugmentedGrid<D> {
    /// The augmented grid of `region`'s walls: boundary points at most `spacing` (m) apart, nodes
    /// closer than `delta` (m) to a wall dropped.
    pub fn new(
        layout: &GridLayout<D>,
        region: &dyn Region<D>,
        spacing: Real,
        walls: Vec<WallContact>,
        delta: Real,
    ) -> Self {
        Self::with_points(layout, region, region.boundary_points(spacing), spacing, walls, delta)
    }

    /// The augmented grid over the given boundary points (sampled at most `spacing` (m) apart).
    pub fn with_points(
        layout: &GridLayout<D>,
        region: &dyn Region<D>,
        points: Vec<BoundaryPoint<D>>,
        spacing: Real,
        walls: Vec<WallContact>,
        delta: Real,
    ) -> Self {
        let n = layout.num_nodes();
        let half_diagonal = 0.5 * layout.h * (D as Real).sqrt();
        let mut grid = Self {
            points: Vec::new(),
            included: vec![false; n],
            closed_form: vec![false; n],
            cell_start: Vec::new(),
            cell_points: Vec::new(),
            walls,
            delta,
            spacing,
            cell_inside: vec![false; n],
            transfer: AugmentedTransfer::default(),
            follow: None,
        };
        for i in 0..n {
            (grid.included[i], grid.cell_inside[i]) = grid.classify(layout, region, i, half_diagonal).0;
        }
        grid.index_points(layout, points);
        // A particle with stencil base b lies in [b + 1/2, b + 3/2) h per axis, so its support
        // is inside ((b − 1) h, (b + 3) h): a boundary point at x can reach bases in (x/h − 3, x/h + 1).
        let mut reached = vec![false; n];
        for p in &grid.points {
            reach_bases(layout, &p.x, |i| reached[i] = true);
        }
        for i in 0..n {
            grid.closed_form[i] = !reached[i] && grid.stencil_included(layout, i);
        }
        grid
    }

    /// Whether node `i` is included (inside the material region and farther than δ from every wall) and
    /// whether its cell lies wholly inside the region, and how far (m) the walls may move before either
    /// can change: the distance of each signed distance from its threshold.
    fn classify(
        &self,
        layout: &GridLayout<D>,
        region: &dyn Region<D>,
        i: usize,
        half_diagonal: Real,
    ) -> ((bool, bool), Real) {
        let node = region.distance(&layout.position(i)).distance;
        // The signed distance is 1-Lipschitz: a cell whose centre lies deeper than its half-diagonal
        // is inside.
        let centre = region.distance(&layout.position(i).add_scalar(0.5 * layout.h)).distance;
        let margin = (node + self.delta).abs().min((centre + half_diagonal).abs());
        ((node < -self.delta, centre < -half_diagonal), margin)
    }

    /// Whether every node of the stencil with base node `i` is included (false where the stencil leaves
    /// the grid).
    fn stencil_included(&self, layout: &GridLayout<D>, i: usize) -> bool {
        let base = layout.coord(i);
        layout.stencil_origin(&base).is_some_and(|origin| {
            (0..crate::math::stencil_len(D))
                .all(|k| self.included[origin + layout.offset(&crate::math::stencil_offset::<D>(k))])
        })
    }

    /// Keeps the points within the grid and sorts them by cell (a counting sort), in the per-cell index.
    fn index_points(&mut self, layout: &GridLayout<D>, points: Vec<BoundaryPoint<D>>) {
        let n = layout.num_nodes();
        let points: Vec<BoundaryPoint<D>> = points.into_iter().filter(|p| cell_of(layout, &p.x).is_some()).collect();
        self.cell_start.clear();
        self.cell_start.resize(n + 1, 0);
        for p in &points {
            self.cell_start[cell_of(layout, &p.x).unwrap() + 1] += 1;
        }
        for c in 0..n {
            self.cell_start[c + 1] += self.cell_start[c];
        }
        let mut fill = self.cell_start.clone();
        self.cell_points.clear();
        self.cell_points.resize(points.len(), 0);
        for (i, p) in points.iter().enumerate() {
            let c = cell_of(layout, &p.x).unwrap();
            self.cell_points[fill[c] as usize] = i as u32;
            fill[c] += 1;
        }
        self.points = points;
    }

    /// The same grid where the walls are now (after they moved). Only what the walls swept is looked at
    /// again: a node is classified again once the walls may have moved (in all, by `Region::sweep` of
    /// each follow) as far as its signed distances were from their thresholds; the closed form is decided
    /// again where a node's inclusion changed or a boundary point came or went; the boundary points are
    /// sampled again and indexed. The result is the grid [`AugmentedGrid::new`] would build there.
    pub fn follow(&mut self, layout: &GridLayout<D>, region: &dyn Region<D>) {
        let n = layout.num_nodes();
        let half_diagonal = 0.5 * layout.h * (D as Real).sqrt();
        // Re-classify a little early: the signed distances round (in f32 by ~1e-7 of the domain's size).
        let slack = (1e-9 * layout.h).max(16.0 * Real::EPSILON * layout.extent().max());
        let sweep = region.sweep();
        let Some(mut follow) = self.follow.take().filter(|_| sweep.is_finite()) else {
            // The first follow: every node, and what the next ones need.
            let walls = std::mem::take(&mut self.walls);
            let transfer = self.transfer;
            *self = Self::new(layout, region, self.spacing, walls, self.delta).with_transfer(transfer);
            let mut follow = Follow { swept: 0.0, due: vec![0.0; n], reached: vec![0; n] };
            for i in 0..n {
                follow.due[i] = self.classify(layout, region, i, half_diagonal).1 - slack;
            }
            for p in &self.points {
                reach_bases(layout, &p.x, |i| follow.reached[i] += 1);
            }
            self.follow = Some(follow);
            return;
        };
        follow.swept += sweep;
        let mut stale = Vec::new();
        for i in 0..n {
            if follow.due[i] <= follow.swept {
                let (flags, margin) = self.classify(layout, region, i, half_diagonal);
                if flags.0 != self.included[i] {
                    stale.push(i);
                }
                (self.included[i], self.cell_inside[i]) = flags;
                follow.due[i] = follow.swept + margin - slack;
            }
        }
        // The stencils that hold a node whose inclusion changed, and the bases the old and new points reach.
        let mut bases = Vec::new();
        for &j in &stale {
            let c = layout.coord(j);
            for k in 0..crate::math::stencil_len(D) {
                let o = crate::math::stencil_offset::<D>(k);
                if let Some(i) = layout.node_index(&std::array::from_fn(|a| c[a] - o[a] as i64)) {
                    bases.push(i);
                }
            }
        }
        for p in &self.points {
            reach_bases(layout, &p.x, |i| {
                follow.reached[i] -= 1;
                bases.push(i);
            });
        }
        self.index_points(layout, region.boundary_points(self.spacing));
        for p in &self.points {
            reach_bases(layout, &p.x, |i| {
                follow.reached[i] += 1;
                bases.push(i);
            });
        }
        for i in bases {
            self.closed_form[i] = follow.reached[i] == 0 && self.stencil_included(layout, i);
        }
        self.follow = Some(follow);
    }

    /// The same grid with transfer `transfer`.
    pub fn with_transfer(mut self, transfer: AugmentedTransfer) -> Self {
        self.transfer = transfer;
        self
    }

    /// Heap bytes of the boundary points, node flags, the per-cell index and what following moving walls
    /// keeps.
    pub fn heap_bytes(&self) -> usize {
        use crate::math::heap_bytes as b;
        b(&self.points)
            + b(&self.included)
            + b(&self.closed_form)
            + b(&self.cell_start)
            + b(&self.cell_points)
            + b(&self.cell_inside)
            + self.follow.as_ref().map_or(0, |f| b(&f.due) + b(&f.reached))
    }

    /// Whether `x` certainly lies inside the material region (its whole cell does); a cheap
    /// test before the exact distance to the walls.
    #[inline]
    pub fn surely_inside(&self, layout: &GridLayout<D>, x: &Vector<D>) -> bool {
        let inv_h = 1.0 / layout.h;
        layout.node_index(&std::array::from_fn(|k| floor_i64(x[k] * inv_h))).is_some_and(|c| self.cell_inside[c])
    }

    /// Number of regular nodes; boundary point `b` is grid point `num_nodes + b`.
    pub fn num_nodes(&self) -> usize {
        self.included.len()
    }

    /// Calls `f(point, w, x_point − x_p)` for each included node of the stencil and,
    /// unless the stencil takes the closed form, each boundary point in the B-spline
    /// support of `x` (looked up in the per-cell index). Returns whether it was closed.
    #[inline]
    pub fn for_each_point(
        &self,
        layout: &GridLayout<D>,
        x: &Vector<D>,
        p: usize,
        mut f: impl FnMut(usize, Real, Vector<D>),
    ) -> Result<bool, OutOfGrid> {
        let closed = self.for_each_node(layout, x, p, &mut f)?;
        if !closed {
            self.scan_points(layout, x, |b, w, d| f(self.num_nodes() + b as usize, w, d));
        }
        Ok(closed)
    }

    /// As [`Self::for_each_point`], with the boundary points remembered in `near`.
    #[inline]
    pub fn for_each_cached(
        &self,
        layout: &GridLayout<D>,
        x: &Vector<D>,
        p: usize,
        near: &NearPoints,
        mut f: impl FnMut(usize, Real, Vector<D>),
    ) -> Result<(), OutOfGrid> {
        if near.len == NearPoints::OVERFLOW {
            return self.for_each_point(layout, x, p, f).map(|_| ());
        }
        self.for_each_node(layout, x, p, &mut f)?;
        let inv_h = 1.0 / layout.h;
        for &b in &near.idx[..near.len as usize] {
            let d = self.points[b as usize].x - x;
            f(self.num_nodes() + b as usize, weight(&d, inv_h), d);
        }
        Ok(())
    }

    /// As [`Self::for_each_cached`], for a particle whose stencil is known to be in the grid.
    #[inline]
    pub fn for_each_near(
        &self,
        layout: &GridLayout<D>,
        x: &Vector<D>,
        near: &NearPoints,
        f: impl FnMut(usize, Real, Vector<D>),
    ) {
        self.for_each_cached(layout, x, 0, near, f).expect("particles were sorted into the grid this step");
    }

    /// As [`Self::for_each_near`] with each weight reweighted by `tilt` ([`Tilt::weight`]). In 3D a node's
    /// exponential is the product of per-axis factors ([`Tilt::node_factors`]): 9 exponentials instead of
    /// 27, equal to rounding; in 2D it is [`Tilt::weight`] itself.
    #[inline]
    pub fn for_each_near_tilted(
        &self,
        layout: &GridLayout<D>,
        x: &Vector<D>,
        near: &NearPoints,
        tilt: &Tilt<D>,
        mut f: impl FnMut(usize, Real, Vector<D>),
    ) {
        if D != 3 || near.len == NearPoints::OVERFLOW {
            return self.for_each_near(layout, x, near, |i, w, d| f(i, tilt.weight(w, &d), d));
        }
        let s = Stencil::new(x, 1.0 / layout.h);
        let origin = layout.stencil_origin(&s.base).expect("particles were sorted into the grid this step");
        match tilt.node_factors(&s, layout.h) {
            None => s.visit(layout.h, layout.strides(), |_, i, w, d| {
                if self.included[origin + i] {
                    f(origin + i, w * tilt.scale, d);
                }
            }),
            Some(e) => s.visit(layout.h, layout.strides(), |o, i, w, d| {
                if self.included[origin + i] {
                    let factor: Real = (0..D).map(|a| e[a][o[a]]).product();
                    f(origin + i, w * tilt.scale * factor, d);
                }
            }),
        }
        let inv_h = 1.0 / layout.h;
        for &b in &near.idx[..near.len as usize] {
            let d = self.points[b as usize].x - x;
            f(self.num_nodes() + b as usize, tilt.weight(weight(&d, inv_h), &d), d);
        }
    }

    /// The included nodes of the stencil at `x`; returns whether the closed form applies.
    #[inline]
    fn for_each_node(
        &self,
        layout: &GridLayout<D>,
        x: &Vector<D>,
        p: usize,
        f: &mut impl FnMut(usize, Real, Vector<D>),
    ) -> Result<bool, OutOfGrid> {
        let s = Stencil::new(x, 1.0 / layout.h);
        let origin = layout.stencil_origin(&s.base).ok_or(OutOfGrid(p))?;
        s.for_each_index(layout.h, origin, layout.strides(), |i, w, d| {
            if self.included[i] {
                f(i, w, d);
            }
        });
        Ok(self.closed_form[origin])
    }

    /// Calls `f(b, w, x_b − x)` for each boundary point `b` with a non-zero weight at `x`.
    #[inline]
    fn scan_points(&self, layout: &GridLayout<D>, x: &Vector<D>, mut f: impl FnMut(u32, Real, Vector<D>)) {
        let inv_h = 1.0 / layout.h;
        let reach = 1.5 * layout.h;
        let lo: [i64; D] = std::array::from_fn(|k| floor_i64((x[k] - reach) * inv_h));
        let hi: [i64; D] = std::array::from_fn(|k| floor_i64((x[k] + reach) * inv_h));
        // The cells from `lo` to `hi`, the first axis fastest, row by row along it: a row's cells are
        // consecutive, so its points are one range of `cell_points` (the same points in the same order
        // as cell by cell). The rows are counted by an odometer over the other axes.
        let (first, last) = (lo[0].max(-GHOST), hi[0].min(layout.dims[0] as i64 - 1 - GHOST));
        if first > last {
            return;
        }
        let mut c = lo;
        c[0] = first;
        loop {
            if let Some(cell) = layout.node_index(&c) {
                let end = cell + (last - first) as usize + 1;
                let range = self.cell_start[cell] as usize..self.cell_start[end] as usize;
                for &b in &self.cell_points[range] {
                    let d = self.points[b as usize].x - x;
                    let w = weight(&d, inv_h);
                    if w > 0.0 {
                        f(b, w, d);
                    }
                }
            }
            let mut a = 1;
            if a == D {
                return;
            }
            loop {
                c[a] += 1;
                if c[a] <= hi[a] {
                    break;
                }
                c[a] = lo[a];
                a += 1;
                if a == D {
                    return;
                }
            }
        }
    }

    /// Whether a particle at `x` has its whole stencil included and no boundary point in reach,
    /// so that its MLS inverse is the closed form of the regular grid.
    #[inline]
    pub fn takes_closed_form(&self, layout: &GridLayout<D>, x: &Vector<D>, p: usize) -> Result<bool, OutOfGrid> {
        let origin = layout.stencil_origin(&Stencil::base_of(x, 1.0 / layout.h)).ok_or(OutOfGrid(p))?;
        Ok(self.closed_form[origin])
    }

    /// The particle's MLS inverse (eq. (5)), closed form where the stencil is whole and no
    /// boundary point is near, and the boundary points it sees, for the later stages.
    pub fn particle_inverse<Ops: DimOps<D>>(
        &self,
        layout: &GridLayout<D>,
        x: &Vector<D>,
        p: usize,
    ) -> Result<(MlsInverse<D>, MlsKind, NearPoints), OutOfGrid> {
        if self.takes_closed_form(layout, x, p)? {
            return Ok((MlsInverse::regular(layout.h), MlsKind::Regular, NearPoints::NONE));
        }
        self.general_inverse::<Ops>(layout, x, p).map(|(minv, kind, near, _)| (minv, kind, near))
    }

    /// The general inverse of eq. (5) over the included nodes and boundary points at `x`, and
    /// the sum of their weights Σw.
    pub fn general_inverse<Ops: DimOps<D>>(
        &self,
        layout: &GridLayout<D>,
        x: &Vector<D>,
        p: usize,
    ) -> Result<(MlsInverse<D>, MlsKind, NearPoints, Real), OutOfGrid> {
        let mut m = Moments::new();
        self.for_each_node(layout, x, p, &mut |_, w, d| m.add(w, &d))?;
        let mut near = NearPoints::NONE;
        self.scan_points(layout, x, |b, w, d| {
            m.add(w, &d);
            near.push(b);
        });
        let (minv, kind) = MlsInverse::from_moments::<Ops>(&m, layout.h);
        Ok((minv, kind, near, m.a))
    }

    /// As [`Self::general_inverse`] with the points' weights reweighted by the particle's [`Tilt`]
    /// (the stable transfer's), which it also returns; Σw is the sum of the B-spline weights, which
    /// the tilt keeps. A particle that sees more than [`MAX_POINTS`] grid points keeps its B-spline
    /// weights (still positive, so the transfer stays energy-stable, but its first moment is not zero:
    /// its P2G and G2P no longer keep momentum exactly).
    pub fn stable_inverse<Ops: DimOps<D>>(
        &self,
        layout: &GridLayout<D>,
        x: &Vector<D>,
        p: usize,
    ) -> Result<(MlsInverse<D>, MlsKind, NearPoints, Real, Tilt<D>), OutOfGrid> {
        // The particle's points (B-spline weight, offset), gathered once for the Newton iterations: its
        // included nodes first, with their stencil offsets, then its boundary points. On the stack and not
        // zeroed (a zeroed array of MAX_POINTS cost ~1% of the 256² augmented step).
        let mut points = arrayvec::ArrayVec::<(Real, Vector<D>), MAX_POINTS>::new();
        let mut offsets = [[0; D]; crate::math::stencil_len(3)];
        let mut seen = 0;
        let mut total = 0.0;
        let mut keep = |w: Real, d: Vector<D>| {
            total += w;
            seen += 1;
            // Past MAX_POINTS, `seen` tells (below): the particle keeps its B-spline weights.
            let _ = points.try_push((w, d));
        };
        let s = Stencil::new(x, 1.0 / layout.h);
        let origin = layout.stencil_origin(&s.base).ok_or(OutOfGrid(p))?;
        let mut nodes = 0;
        s.visit(layout.h, layout.strides(), |o, i, w, d| {
            if self.included[origin + i] {
                keep(w, d);
                offsets[nodes] = o;
                nodes += 1;
            }
        });
        let mut near = NearPoints::NONE;
        self.scan_points(layout, x, |b, w, d| {
            keep(w, d);
            near.push(b);
        });
        let (tilt, m) = if seen > points.len() {
            let mut m = Moments::new();
            self.for_each_near(layout, x, &near, |_, w, d| m.add(w, &d));
            (Tilt::none(), m)
        } else {
            centred_tilt::<D, Ops>(&points, &offsets[..nodes], &s.fx, 1.0 / layout.h, total)
        };
        let (minv, kind) = MlsInverse::from_moments::<Ops>(&m, layout.h);
        Ok((minv, kind, near, total, tilt))
    }

    /// MLS reconstruction (eq. (4)) at `x` of a scalar field given at the grid points
    /// (`values[i]` for node `i`, `values[num_nodes + b]` for boundary point `b`):
    /// the value, its gradient, and how the MLS system was solved.
    pub fn interpolate<Ops: DimOps<D>>(
        &self,
        layout: &GridLayout<D>,
        x: &Vector<D>,
        values: &[Real],
    ) -> Result<(Real, Vector<D>, MlsKind), OutOfGrid> {
        let (minv, kind, _) = self.particle_inverse::<Ops>(layout, x, 0)?;
        let (mut u, mut grad) = (0.0, Vector::<D>::zeros());
        self.for_each_point(layout, x, 0, |i, w, d| {
            let (phi, g) = minv.shape(w, &d);
            u += phi * values[i];
            grad += g * values[i];
        })?;
        Ok((u, grad, kind))
    }

    /// Wall conditions at the boundary points (grid points `num_nodes..`), after momentum → velocity;
    /// each wall's impulse on the grid there, `m_b (v_b' − v_b)` (N·s), is added to `impulse` at the point.
    pub fn apply(&self, mass: &[Real], velocity: &mut [Vector<D>], impulse: &mut WallImpulses<D>) {
        let base = self.num_nodes();
        for (b, p) in self.points.iter().enumerate() {
            let i = base + b;
            let condition = self.walls[p.wall];
            // A point no particle gave mass to moves with the wall (and carries no momentum).
            if mass[i] != 0.0 {
                let before = velocity[i];
                velocity[i] = condition.apply_at(before, &p.normals, &p.velocity);
                impulse.add(p.wall, &p.x, (velocity[i] - before) * mass[i]);
            } else {
                velocity[i] = condition.apply_at(p.velocity, &p.normals, &p.velocity);
            }
        }
    }
}

/// The particles of one step whose MLS system sees a wall (not the closed form), with their
/// inverses and boundary points: computed once per step and read by P2G and G2P. Particles
/// away from walls take the closed form and have no entry, so the table costs memory only for
/// the particles near walls.
#[derive(Clone, Debug, Default)]
pub struct WallParticles<const D: usize> {
    /// One bit per particle, 64 to a word: whether it has an entry (bit `p % 64` of word `p / 64`).
    has_entry: Vec<u64>,
    /// Per word of `has_entry`: the entries of the particles before it. A particle's entry is this plus
    /// the bits set below its own (half a byte per 64 particles where a slot per particle took 4 B each).
    entries_before: Vec<u32>,
    /// Per entry: the particle, its inverse, the boundary points it sees and the sum Σw of the
    /// weights of its grid points.
    particle: Vec<u32>,
    minv: Vec<MlsInverse<D>>,
    near: Vec<NearPoints>,
    total: Vec<Real>,
    tilt: Vec<Tilt<D>>,
}

/// A particle's entry in [`WallParticles`].
#[derive(Clone, Copy, Debug)]
pub struct WallEntry<'a, const D: usize> {
    /// Its MLS inverse (eq. (5)), over the reweighted points for the stable transfer.
    pub minv: &'a MlsInverse<D>,
    /// The boundary points it sees.
    pub near: &'a NearPoints,
    /// Σw, the sum of its grid points' B-spline weights.
    pub total: Real,
    /// Its reweighting ([`Tilt::none`] for the paper's transfer).
    pub tilt: Tilt<D>,
    /// Its index in the table (entries are in particle order).
    pub slot: usize,
}

impl<const D: usize> WallEntry<'_, D> {
    /// The stable transfer's affine velocity (1/s) of the particle over its own grid points this step,
    /// from the affine state `c` (1/s) it keeps between steps; [`WallEntry::kept_affine`] is the way
    /// back. Particles keep APIC's spin over the regular second moment, `m h²/4 axial(c)` (h in m): over
    /// its grid points, whose second moment `Σ ŵ d dᵀ` is not h²/4 I next to a wall and changes as it
    /// moves, the particle's affine velocity differs from `c` by the rotation rate that gives the grid
    /// that same angular momentum ([`keep_spin`]); its strain rate is `c`'s. So a particle gives the grid
    /// the angular momentum it took from it (exactly where its weights are centred); the paper's transfer
    /// keeps the velocity gradient instead.
    pub fn affine_velocity<Ops: DimOps<D>>(&self, c: &Matrix<D>, h: Real) -> Matrix<D> {
        self.carry_spin::<Ops>(c, h, true)
    }

    /// The affine state the particle keeps between steps of the affine velocity `c` (1/s) fitted over its
    /// grid points this step: [`WallEntry::affine_velocity`] inverted.
    pub fn kept_affine<Ops: DimOps<D>>(&self, c: &Matrix<D>, h: Real) -> Matrix<D> {
        self.carry_spin::<Ops>(c, h, false)
    }

    /// `c` carried from the regular second moment to the particle's own (`to_own`) or back.
    fn carry_spin<Ops: DimOps<D>>(&self, c: &Matrix<D>, h: Real, to_own: bool) -> Matrix<D> {
        let Some(own) = self.minv.second_moment::<Ops>(self.total) else { return *c };
        let regular = regular_moment::<D>(h);
        if to_own {
            keep_spin(c, &regular, &own)
        } else {
            keep_spin(c, &own, &regular)
        }
    }
}

/// The second moment `Σ w d dᵀ` (m²) of the quadratic B-spline weights of a whole stencil, `h²/4 I`.
fn regular_moment<const D: usize>(h: Real) -> Matrix<D> {
    Matrix::<D>::identity() * (0.25 * h * h)
}

impl<const D: usize> WallParticles<D> {
    /// Finds the particles at `x` near walls and solves their MLS systems (eq. (5)). Returns
    /// how many were ill-conditioned or isolated. Allocates only when the table grows.
    pub fn update<Ops: DimOps<D>>(
        &mut self,
        grid: &AugmentedGrid<D>,
        layout: &GridLayout<D>,
        x: &[Vector<D>],
    ) -> Result<u64, OutOfGrid> {
        use rayon::prelude::*;
        let parallel = crate::parallel::worth_splitting(x.len());
        let min_task = if parallel { crate::parallel::task_len(x.len()) } else { usize::MAX };
        let words = x.len().div_ceil(64);
        self.has_entry.resize(words, 0);
        self.has_entry.par_iter_mut().zip(x.par_chunks(64)).enumerate().with_min_len(min_task / 64).try_for_each(
            |(w, (bits, xs))| {
                *bits = 0;
                for (b, xp) in xs.iter().enumerate() {
                    if !grid.takes_closed_form(layout, xp, 64 * w + b)? {
                        *bits |= 1 << b;
                    }
                }
                Ok(())
            },
        )?;
        // Entries in particle order (a serial pass over the words).
        self.entries_before.resize(words, 0);
        let mut m = 0;
        for (before, bits) in self.entries_before.iter_mut().zip(&self.has_entry) {
            *before = m;
            m += bits.count_ones();
        }
        let m = m as usize;
        resize_with_margin(&mut self.particle, m, 0);
        let mut next = 0;
        for (w, &bits) in self.has_entry.iter().enumerate() {
            let mut rest = bits;
            while rest != 0 {
                self.particle[next] = (64 * w) as u32 + rest.trailing_zeros();
                rest &= rest - 1;
                next += 1;
            }
        }
        resize_with_margin(&mut self.minv, m, MlsInverse::regular(layout.h));
        resize_with_margin(&mut self.near, m, NearPoints::NONE);
        resize_with_margin(&mut self.total, m, 0.0);
        resize_with_margin(&mut self.tilt, m, Tilt::none());
        let stable = grid.transfer == AugmentedTransfer::Stable;
        self.minv
            .par_iter_mut()
            .zip(self.near.par_iter_mut())
            .zip(self.total.par_iter_mut())
            .zip(self.tilt.par_iter_mut())
            .zip(self.particle.par_iter())
            .with_min_len(if parallel { 256 } else { usize::MAX })
            .map(|((((minv, near), total), tilt), &p)| {
                let (x, p) = (&x[p as usize], p as usize);
                let kind;
                if stable {
                    (*minv, kind, *near, *total, *tilt) = grid.stable_inverse::<Ops>(layout, x, p)?;
                } else {
                    (*minv, kind, *near, *total) = grid.general_inverse::<Ops>(layout, x, p)?;
                    *tilt = Tilt::none();
                }
                Ok(u64::from(matches!(kind, MlsKind::Regularized | MlsKind::Isolated)))
            })
            .sum()
    }

    /// The table entry of particle `p`, if its MLS system sees a wall (asked of every particle in P2G and
    /// G2P: inlined, most answers are one bit test).
    #[inline(always)]
    pub fn entry(&self, p: usize) -> Option<WallEntry<'_, D>> {
        let bits = *self.has_entry.get(p / 64)?;
        let below = 1u64 << (p % 64);
        if bits & below == 0 {
            return None;
        }
        let s = self.entries_before[p / 64] as usize + (bits & (below - 1)).count_ones() as usize;
        Some(WallEntry { minv: &self.minv[s], near: &self.near[s], total: self.total[s], tilt: self.tilt[s], slot: s })
    }

    /// Heap bytes of the table (`has_entry` and `entries_before` are per 64 particles, the rest per
    /// particle near a wall).
    pub fn heap_bytes(&self) -> usize {
        use crate::math::heap_bytes as b;
        b(&self.has_entry)
            + b(&self.entries_before)
            + b(&self.particle)
            + b(&self.minv)
            + b(&self.near)
            + b(&self.total)
            + b(&self.tilt)
    }

    /// Number of particles whose MLS system sees a wall.
    pub fn len(&self) -> usize {
        self.particle.len()
    }

    pub fn is_empty(&self) -> bool {
        self.particle.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Circle, Point, Polygon, Side, WallShape, Walls2};
    use crate::motion::Motion;

    /// Following walls only where they swept builds the grid a full build would: the same boundary
    /// points, included nodes, closed-form bases, point index and inside cells after each of 200 steps of
    /// a tilted tank shaken and turned about its centre and a circle carried on a path through it.
    #[test]
    fn following_what_the_walls_swept_is_a_full_build() {
        let layout = GridLayout::<2>::new(1.0 / 48.0, [48, 48]);
        let tank = Polygon::new(vec![
            Point::new(0.15, 0.12),
            Point::new(0.82, 0.238),
            Point::new(0.73, 0.75),
            Point::new(0.06, 0.632),
        ]);
        let shake = Motion::Oscillation {
            amplitude: [0.05, 0.02],
            angular_amplitude: 0.3,
            frequency: 2.0,
            phase: 0.0,
            pivot: None,
        };
        let path = Motion::Keyframes {
            times: vec![0.0, 0.2, 0.4],
            positions: vec![[0.0, 0.0], [0.2, 0.05], [0.1, 0.2]],
            angles: None,
            pivot: None,
        };
        let disk = Circle { center: Point::new(0.4, 0.35), radius: 0.08 };
        let walls = vec![WallShape::Polygon(tank), WallShape::Circle(disk, Side::Outside)];
        let mut region = Walls2::new(walls, Point::new(1.0, 1.0)).with_moves(vec![Some(shake), Some(path)]);
        let contacts = vec![WallContact::from(crate::wall::WallCondition::Slip); 3];
        follow_and_compare(&layout, &mut region, &contacts, 200);
    }

    /// The wall table gives entries to exactly the particles that do not take the closed form, numbered in
    /// particle order across the 64-particle words of its bit index (200 then 130 particles on a line that
    /// comes near a tilted wall, so words hold none or some of their particles near it, and the last word is
    /// partly filled).
    #[test]
    fn the_table_numbers_the_particles_near_walls_in_order() {
        let layout = GridLayout::<2>::new(1.0 / 32.0, [32, 32]);
        let tank =
            Polygon::new(vec![Point::new(0.1, 0.1), Point::new(0.9, 0.2), Point::new(0.9, 0.9), Point::new(0.1, 0.9)]);
        let region = Walls2::new(vec![WallShape::Polygon(tank)], Point::new(1.0, 1.0));
        let contacts = vec![WallContact::from(crate::wall::WallCondition::Slip); 2];
        let grid = AugmentedGrid::new(&layout, &region, layout.h, contacts, 0.1 * layout.h);
        let mut table = WallParticles::<2>::default();
        for n in [200, 130] {
            // Down the middle, from the top (away from walls) to the floor, then back up.
            let x: Vec<Vector<2>> = (0..n)
                .map(|p| {
                    let t = (p as Real / (n - 1) as Real * 2.0 - 1.0).abs();
                    Vector::<2>::new(0.5, 0.16 + 0.7 * t)
                })
                .collect();
            table.update::<crate::math::Dim<2>>(&grid, &layout, &x).unwrap();
            let near: Vec<usize> = (0..n).filter(|&p| !grid.takes_closed_form(&layout, &x[p], p).unwrap()).collect();
            assert!(!near.is_empty() && near.len() < n / 2, "{} of {n} near the floor", near.len());
            assert_eq!(table.len(), near.len());
            for p in 0..n + 10 {
                let slot = table.entry(p).map(|e| e.slot);
                assert_eq!(slot, near.iter().position(|&q| q == p), "particle {p} of {n}");
            }
        }
    }

    /// Steps the walls of `region` `steps` times (2 ms each) and checks, after each, that following them
    /// built what a full build of the grid would.
    fn follow_and_compare<const D: usize>(
        layout: &GridLayout<D>,
        region: &mut dyn Region<D>,
        contacts: &[WallContact],
        steps: usize,
    ) {
        let (spacing, delta) = (layout.h, 0.1 * layout.h);
        let mut grid = AugmentedGrid::new(layout, region, spacing, contacts.to_vec(), delta);
        let dt = 2e-3;
        for step in 0..steps {
            region.set_time(step as Real * dt, dt);
            grid.follow(layout, region);
            let full = AugmentedGrid::new(layout, region, spacing, contacts.to_vec(), delta);
            assert_eq!(grid.points, full.points, "step {step}");
            assert!(grid.included == full.included, "step {step}: included");
            assert!(grid.closed_form == full.closed_form, "step {step}: closed form");
            assert!(grid.cell_start == full.cell_start && grid.cell_points == full.cell_points, "step {step}: index");
            assert!(grid.cell_inside == full.cell_inside, "step {step}: inside cells");
        }
    }

    /// A box tank turned 0.3 rad about (1, 0.2, 0.6), an axis in no coordinate plane, in the unit cube.
    fn turned_tank() -> crate::geometry3::Solid {
        let axes =
            nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(Vector::<3>::new(1.0, 0.2, 0.6)), 0.3);
        crate::geometry3::Solid::Box {
            centre: Vector::<3>::new(0.5, 0.45, 0.5),
            half: Vector::<3>::new(0.3, 0.25, 0.25),
            axes: axes.into_inner(),
        }
    }

    /// In 3D too: a box container shaken and turned about an axis in no coordinate plane and a sphere
    /// carried through it, 120 steps, the followed grid equal to a full build after each.
    #[test]
    fn following_3d_walls_is_a_full_build() {
        use crate::geometry3::{Solid, Wall3, Walls3};
        use crate::motion::Motion3;
        let layout = GridLayout::<3>::new(1.0 / 20.0, [20, 20, 20]);
        let tank = turned_tank();
        let ball = Solid::Sphere { centre: Vector::<3>::new(0.4, 0.4, 0.45), radius: 0.08 };
        let shake = Motion3::Oscillation {
            amplitude: [0.05, 0.0, 0.02],
            angular_amplitude: [0.0, 0.1, 0.2],
            frequency: 2.0,
            phase: 0.0,
            pivot: None,
        };
        let path = Motion3::Keyframes {
            times: vec![0.0, 0.1, 0.24],
            positions: vec![[0.0; 3], [0.1, 0.05, 0.0], [0.15, 0.1, 0.05]],
            rotations: None,
            pivot: None,
        };
        let walls = vec![Wall3 { solid: tank, side: Side::Inside }, Wall3 { solid: ball, side: Side::Outside }];
        let mut region = Walls3::new(walls, Vector::<3>::new(1.0, 1.0, 1.0))
            .with_moves(vec![Some(shake), Some(path)])
            .expect("no plane moves");
        let contacts = vec![WallContact::from(crate::wall::WallCondition::Slip); 3];
        follow_and_compare(&layout, &mut region, &contacts, 120);
    }

    /// The stable transfer's reweighting in 3D, with the nodes' exponentials as products of per-axis
    /// factors: every weight equals `Tilt::weight` to 1e-12 relative and the weights keep Σw; the
    /// reweighted points of particles near the faces, edges and corners of a turned box have their first
    /// moment at the particle (below 1e-10 h of Σw) unless the tilt was capped or the spread floor stopped
    /// it (measured: 1,407 of 1,438 uncapped particles centred, those that see more boundary points than
    /// the table remembers included; 1,211 of the 1,239 others before they were centred too).
    #[test]
    fn the_3d_tilt_centres_the_points_with_factored_exponentials() {
        use crate::geometry3::{Wall3, Walls3};
        let layout = GridLayout::<3>::new(1.0 / 20.0, [20, 20, 20]);
        let tank = turned_tank();
        let region = Walls3::new(vec![Wall3 { solid: tank, side: Side::Inside }], Vector::<3>::new(1.0, 1.0, 1.0));
        let contacts = vec![WallContact::from(crate::wall::WallCondition::Slip); 2];
        let mut grid = AugmentedGrid::new(&layout, &region, layout.h, contacts, 0.1 * layout.h);
        grid.transfer = AugmentedTransfer::Stable;
        let (mut tested, mut centred, mut s) = (0, 0, 0x2545f4914f6cdd1du64);
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as Real / (1u64 << 53) as Real
        };
        for _ in 0..3000 {
            let x = Vector::<3>::new(0.15 + 0.7 * next(), 0.15 + 0.6 * next(), 0.2 + 0.6 * next());
            let inside = region.distance(&x).distance;
            if inside >= -0.05 * layout.h || grid.takes_closed_form(&layout, &x, 0).unwrap() {
                continue;
            }
            let (_, _, near, total, tilt) = grid.stable_inverse::<crate::math::Dim<3>>(&layout, &x, 0).unwrap();
            if tilt.eta.norm() * layout.h >= TILT_MAX * (1.0 - 1e-9) {
                continue;
            }
            let (mut sum, mut first) = (0.0, Vector::<3>::zeros());
            grid.for_each_near_tilted(&layout, &x, &near, &tilt, |i, w, d| {
                let plain = if i < grid.num_nodes() { crate::kernel::weight(&d, 1.0 / layout.h) } else { w };
                if i < grid.num_nodes() {
                    let direct = tilt.weight(plain, &d);
                    assert!((w - direct).abs() <= 1e-12 * direct, "{w} against {direct}");
                }
                sum += w;
                first += d * w;
            });
            assert!((sum - total).abs() < 1e-9 * total, "the tilt keeps Σw: {sum} against {total}");
            centred += usize::from(first.norm() < 1e-10 * layout.h * total);
            tested += 1;
        }
        assert!(tested > 1000, "only {tested} particles near a wall");
        assert!(centred as f64 > 0.95 * tested as f64, "{centred} of {tested} centred");
    }
}
