//! The grid→particle fit of the stable augmented transfer: a particle's affine velocity
//! `u(x) = v + C (x − x_p)` is the weighted least-squares fit of eq. (3)–(4) of Toyota & Umetani
//! 2024 to its grid points, plus, for each wall face within reach, the wall's condition at the
//! particle's foot on that face, weighted like (h/r)² as the distance r to the face vanishes
//! (the interpolating MLS of Schaefer et al. 2006 in spirit). The fit then meets the wall value
//! at the wall, so the normal velocity of a particle at distance r from a still wall is O(r) and
//! an explicit step cannot carry it through (derivation: `docs/stable_transfer.md`).
//!
//! The wall terms carry no mass and only penalise the fit, so they can only lower the fit's
//! weighted norm (`Σ w |u(x_i)|²` over the grid points) below that of the grid data when their
//! targets are zero: the transfer stays energy-stable.

use crate::geometry::{WallFeet, MAX_FEET};
use crate::kernel::{bspline, MlsInverse};
use crate::math::{wide, Matrix, Real, Vector};
use crate::wall::{coulomb_kept, moment, WallCondition, WallContact};

/// How far inside a face (cell widths) a particle found past it is taken back to over a step.
pub const PULL_MARGIN: Real = 1e-9;

/// The most (cell widths) a particle found past a face is taken back in one step: a deep one (a failure
/// elsewhere) comes back gradually rather than in a jump.
pub const PULL_MAX: Real = 0.05;

/// Most wall terms of one particle: every foot, each with up to three rows (sticky in 3D).
const MAX_ROWS: usize = MAX_FEET * 3;

/// The velocity change (m/s) each wall gave one particle in G2P, by wall (at most one per foot), with
/// its moment about the origin (m²/s) taken where the wall gave it: times the particle's mass, the
/// impulse of the wall on it and that impulse's moment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WallPush<const D: usize> {
    wall: [u32; MAX_FEET],
    dv: [Vector<D>; MAX_FEET],
    /// Each moment's components about the axes a D-dimensional body turns about (`pack`): z in 2D, all
    /// three in 3D. Each particle near a wall holds a push; 3-vectors in 2D took 32 B more.
    moment: [Vector<D>; MAX_FEET],
}

/// A moment (only z in 2D) as the D reals [`WallPush`] keeps: (z, 0) in 2D.
#[inline]
fn pack<const D: usize>(l: &Vector<3>) -> Vector<D> {
    Vector::<D>::from_fn(|k, _| {
        if D == 2 {
            if k == 0 {
                l.z
            } else {
                0.0
            }
        } else {
            l[k]
        }
    })
}

/// The moment [`pack`] packed.
#[inline]
fn unpack<const D: usize>(l: &Vector<D>) -> Vector<3> {
    if D == 2 {
        Vector::<3>::new(0.0, 0.0, l[0])
    } else {
        Vector::<3>::from_fn(|k, _| l[k])
    }
}

impl<const D: usize> WallPush<D> {
    const EMPTY: u32 = u32::MAX;

    /// No wall pushed.
    pub fn none() -> Self {
        Self {
            wall: [Self::EMPTY; MAX_FEET],
            dv: [Vector::<D>::zeros(); MAX_FEET],
            moment: [Vector::<D>::zeros(); MAX_FEET],
        }
    }

    /// Adds `dv` (m/s), given at `at` (m), to what wall `wall` gave.
    pub fn add(&mut self, wall: usize, dv: Vector<D>, at: &Vector<D>) {
        let slot = self.wall.iter().position(|&w| w == wall as u32 || w == Self::EMPTY);
        // There are at most MAX_FEET walls in reach of a particle: a slot is always left.
        if let Some(k) = slot {
            self.wall[k] = wall as u32;
            self.dv[k] += dv;
            self.moment[k] += pack(&moment(at, &dv));
        }
    }

    /// The impulses of the walls on a particle of mass `m` and their moments: each velocity change times
    /// `m`.
    pub fn given(mut self, m: Real) -> Self {
        for (dv, l) in self.dv.iter_mut().zip(&mut self.moment) {
            *dv *= m;
            *l *= m;
        }
        self
    }

    /// Each wall that pushed, the velocity change it gave and its moment about the origin.
    pub fn iter(&self) -> impl Iterator<Item = (usize, Vector<D>, Vector<3>)> + '_ {
        (self.wall.iter().zip(&self.dv).zip(&self.moment))
            .take_while(|((&w, _), _)| w != Self::EMPTY)
            .map(|((&w, &dv), l)| (w as usize, dv, unpack(l)))
    }
}

/// The inverse `r² / N(r)` of a wall term's weight `ω = N(r) / r²` at distance `r` (cell widths)
/// from its face: the quadratic B-spline over the squared distance. Zero on the face, where the fit
/// meets the wall value exactly; infinite beyond the support (r ≥ 1.5), where the term is dropped.
/// Kept as its inverse so that no weight overflows as r → 0.
#[inline]
pub fn inverse_wall_weight(r: Real) -> Real {
    let n = bspline(r);
    if n > 0.0 {
        r * r / n
    } else {
        Real::INFINITY
    }
}

/// One scalar wall condition on the fit: `n · u(x_p + d) = target`, with weight `1 / inv_weight`.
#[derive(Clone, Copy, Debug)]
struct Row<const D: usize> {
    /// The wall of the foot it belongs to.
    wall: usize,
    n: Vector<D>,
    d: Vector<D>,
    /// `M⁻¹ [1, d]`: its first entry and the rest (the shape function of the foot, eq. (4)).
    q0: Real,
    q: Vector<D>,
    /// `1 / ω`.
    inv_weight: Real,
    /// `target − n · u₀(x_p + d)`, the residual of the fit without wall terms.
    residual: Real,
}

/// Corrects the grid fit `(v, c)` of a particle at `x` (its MLS inverse `minv` over the grid
/// points, eq. (5); `h` the cell width (m), `dt` the step (s)) by the wall terms of `feet` under
/// each wall's condition in `conditions`: sticky asks for the wall's tangential velocity (every component; all of
/// a moving wall's velocity), slip for no normal velocity (relative to a moving wall),
/// separate for no normal velocity only where the fit moves into the wall. Returns the change of `v`
/// each wall made.
///
/// On a face that curves around the material (a circular container), a particle that moves along
/// it in a straight step of `dt` (s) would end `√(ρ² + |v_t dt|²) − ρ` farther out (ρ its distance
/// from the centre): the normal target is inward by `(ρ − √(ρ² − |v_t dt|²)) / dt`, so that
/// explicit advection keeps the particle's distance to the centre (a correction of order dt,
/// zero on straight faces).
///
/// The corrected fit minimises `Σ_i w_i |v_i − u(x_i)|² + Σ_j ω_j (n_j·u(x_j) − g_j)²`. With
/// `A = I ⊗ M` the grid part and `U` the wall rows, Woodbury gives the correction
/// `A⁻¹ U λ` with `(Ω⁻¹ + Uᵀ A⁻¹ U) λ = g − Uᵀ x₀`: a small system per particle whose matrix stays
/// well scaled however large the weights grow (`Ω⁻¹ → 0`).
pub fn fit_to_walls<const D: usize>(
    minv: &MlsInverse<D>,
    x: &Vector<D>,
    feet: &WallFeet<D>,
    conditions: &[WallContact],
    (h, dt): (Real, Real),
    v: &mut Vector<D>,
    c: &mut Matrix<D>,
) -> WallPush<D> {
    let zero = Vector::<D>::zeros();
    let mut rows = [Row { wall: 0, n: zero, d: zero, q0: 0.0, q: zero, inv_weight: 1.0, residual: 0.0 }; MAX_ROWS];
    let mut len = 0;
    let pull = pull_back(feet, h, dt);
    for foot in feet.iter() {
        let d = foot.x - x;
        let inv_weight = inverse_wall_weight(d.norm() / h);
        if !inv_weight.is_finite() {
            continue;
        }
        let (q0, q) = minv.shape(1.0, &d);
        let fitted = *v + *c * d;
        let n = foot.normal;
        let inward = if foot.curvature > 0.0 && dt > 0.0 {
            // The particle's distance from the circle's centre (the foot lies a radius out along n).
            let rho = (*x - (foot.x - n / foot.curvature)).norm();
            // Along the face relative to its centre of curvature, which a moving wall carries (a circle
            // turning about its centre stays where it is).
            let along = if conditions[foot.wall].moving { *v - foot.centre_velocity } else { *v };
            let step = (along - n * n.dot(&along)).norm() * dt;
            // Inward by δ with (ρ − δ)² + step² = ρ²: the step's chord ends at ρ again.
            (rho - (rho * rho - step * step).max(0.0).sqrt()) / dt
        } else {
            0.0
        };
        let contact = conditions[foot.wall];
        // A straight face of a turning wall: the particle must end the step on the face where it is then,
        // so its velocity along the face's normal at the end of the step is the wall point's.
        let n = if contact.moving && foot.curvature == 0.0 { foot.normal_next } else { n };
        // A face the particle lies past asks it back inside (`pull_back`), the same for every such face.
        let (pull, pulled) = if foot.is_pinned() { (pull, -n.dot(&pull)) } else { (zero, 0.0) };
        let mut row = |n: Vector<D>, target: Real| {
            if len < MAX_ROWS {
                rows[len] = Row { wall: foot.wall, n, d, q0, q, inv_weight, residual: target - n.dot(&fitted) };
                len += 1;
            }
        };
        if contact.moving {
            // A wall moving as a rigid body: its conditions hold relative to its whole velocity. The normal
            // velocity of a curved face is its centre's (a circle turning about its centre stays put; the
            // chord of its surface points' paths is what `inward` corrects).
            let wall_n = if foot.curvature > 0.0 { n.dot(&foot.centre_velocity) } else { n.dot(&foot.velocity) };
            match contact.condition {
                WallCondition::Sticky => {
                    let wall = foot.velocity + n * (wall_n - n.dot(&foot.velocity) - inward) + pull;
                    each_axis(&wall, &mut row);
                }
                WallCondition::Slip => row(n, wall_n - inward - pulled),
                WallCondition::Separate => {
                    let pressed = n.dot(&fitted) - wall_n + inward + pulled;
                    if pressed > 0.0 && contact.friction > 0.0 {
                        let slide = fitted - n * n.dot(&fitted) - (foot.velocity - n * wall_n);
                        let kept = coulomb_kept(contact.friction, pressed, slide.norm());
                        let target =
                            foot.velocity + n * (wall_n - n.dot(&foot.velocity) - inward) + slide * kept + pull;
                        each_axis(&target, &mut row);
                    } else if pressed > 0.0 {
                        row(n, wall_n - inward - pulled)
                    }
                }
            }
            continue;
        }
        match contact.condition {
            WallCondition::Sticky => {
                // The wall's geometry is still: only its tangential surface velocity counts.
                let wall = foot.velocity - n * (n.dot(&foot.velocity) + inward) + pull;
                each_axis(&wall, &mut row);
            }
            WallCondition::Slip => row(n, -inward - pulled),
            WallCondition::Separate if contact.friction > 0.0 => {
                // In contact, the fit meets the Coulomb update of its own value at the foot (the same
                // cone as at the grid points): every component, like a sticky wall moving at it.
                let pressed = n.dot(&fitted) + inward + pulled;
                if pressed > 0.0 {
                    let wall_t = foot.velocity - n * n.dot(&foot.velocity);
                    let slide = fitted - n * n.dot(&fitted) - wall_t;
                    let kept = coulomb_kept(contact.friction, pressed, slide.norm());
                    let target = wall_t + slide * kept - n * inward + pull;
                    each_axis(&target, &mut row);
                }
            }
            WallCondition::Separate => {
                if n.dot(&fitted) > -inward - pulled {
                    row(n, -inward - pulled)
                }
            }
        }
    }
    let mut push = WallPush::none();
    apply_rows(&rows[..len], x, v, c, &mut push);
    push
}

/// The velocity (m/s) that takes a particle lying past some faces (their feet pinned to it, at `depth`
/// past each) back to [`PULL_MARGIN`] cells (of `h`, m) inside all of them over a step of `dt` (s), or
/// [`PULL_MAX`] cells closer where it lies deeper:
/// `P = Σ a_k n_k` with `n_j · P = −(min(depth_j, PULL_MAX h) + PULL_MARGIN h) / dt` for every such face (faces whose
/// normals depend on the others add nothing), shortened to PULL_MAX cells a step where faces at a sharp
/// angle would ask for more. Zero for a particle past no face. Its part along each
/// face goes into the wall conditions' targets there, so that rounding cannot leave a particle past a
/// wall for good; one within the margin of a face (pinned there, `depth` > −margin) is asked to the
/// margin, so that a particle sliding on a face keeps the margin from it instead of stepping in and out
/// of it by rounding.
fn pull_back<const D: usize>(feet: &WallFeet<D>, h: Real, dt: Real) -> Vector<D> {
    let mut normals = [Vector::<D>::zeros(); MAX_FEET];
    let mut k = [[0.0f64; MAX_FEET + 1]; MAX_FEET];
    let mut m = 0;
    for foot in feet.iter().filter(|f| f.is_pinned()) {
        normals[m] = foot.normal;
        k[m][MAX_FEET] = -wide((foot.depth.min(PULL_MAX * h) + PULL_MARGIN * h).max(0.0) / dt);
        m += 1;
    }
    if m == 0 || dt <= 0.0 {
        return Vector::<D>::zeros();
    }
    for j in 0..m {
        for l in 0..m {
            k[j][l] = wide(normals[j].dot(&normals[l]));
        }
        k[j][m] = k[j][MAX_FEET];
    }
    let a = solve(&mut k, m);
    let pull = (0..m).fold(Vector::<D>::zeros(), |p, j| p + normals[j] * a[j] as Real);
    // Faces at a sharp angle would ask for a long move: never more than PULL_MAX (and the margin) a step.
    let most = (PULL_MAX + PULL_MARGIN) * h / dt;
    let norm = pull.norm();
    if norm > most {
        pull * (most / norm)
    } else {
        pull
    }
}

/// Solves the `m` × `m` system in the first `m` columns of `k` with right-hand side in column `m`
/// (Gaussian elimination with partial pivoting, in f64); an unknown whose row depends on the others
/// (its pivot below 1e-12 of the largest diagonal) is set to zero.
fn solve<const N: usize>(k: &mut [[f64; N]], m: usize) -> [f64; MAX_ROWS] {
    let scale = (0..m).map(|j| k[j][j].abs()).fold(0.0, f64::max);
    let mut dependent = [false; MAX_ROWS];
    for col in 0..m {
        let pivot = (col..m).max_by(|&a, &b| k[a][col].abs().total_cmp(&k[b][col].abs())).unwrap_or(col);
        k.swap(col, pivot);
        let p = k[col][col];
        if p.abs() <= 1e-12 * scale || p.abs() < 1e-300 {
            dependent[col] = true;
            continue;
        }
        for row in col + 1..m {
            let f = k[row][col] / p;
            for l in col..=m {
                k[row][l] -= f * k[col][l];
            }
        }
    }
    let mut x = [0.0f64; MAX_ROWS];
    for j in (0..m).rev() {
        if dependent[j] {
            continue;
        }
        let s: f64 = (j + 1..m).map(|l| k[j][l] * x[l]).sum();
        x[j] = (k[j][m] - s) / k[j][j];
    }
    x
}

/// One wall row per axis, asking every component of the fit at the foot for `target`.
#[inline]
fn each_axis<const D: usize>(target: &Vector<D>, row: &mut impl FnMut(Vector<D>, Real)) {
    for k in 0..D {
        let mut axis = Vector::<D>::zeros();
        axis[k] = 1.0;
        row(axis, target[k]);
    }
}

/// Solves `(Ω⁻¹ + Uᵀ A⁻¹ U) λ = residual` in f64 (at most [`MAX_ROWS`] unknowns, Gaussian
/// elimination with partial pivoting) and adds `Σ_j λ_j n_j [q0_j, q_jᵀ]` to the fit of the particle at
/// `x`, each row's part of `v` to its wall's `push`, given at the row's foot: a row changes the
/// particle's momentum over its grid points as an impulse there (`docs/stable_transfer.md`, Momentum),
/// so its moment counts both the change of `v` and the spin of its change of `c`.
fn apply_rows<const D: usize>(
    rows: &[Row<D>],
    x: &Vector<D>,
    v: &mut Vector<D>,
    c: &mut Matrix<D>,
    push: &mut WallPush<D>,
) {
    let m = rows.len();
    if m == 0 {
        return;
    }
    let mut k = [[0.0f64; MAX_ROWS + 1]; MAX_ROWS];
    for (j, a) in rows.iter().enumerate() {
        for (l, b) in rows.iter().enumerate() {
            // P_jᵀ M⁻¹ P_l = q0_l + d_j · q_l.
            k[j][l] = wide(a.n.dot(&b.n)) * wide(b.q0 + a.d.dot(&b.q));
        }
        k[j][j] += wide(a.inv_weight);
        k[j][m] = wide(a.residual);
    }
    // A row that depends on the others (two sticky faces pinned at one particle ask the same of it)
    // gets no multiplier of its own: the consistent system is solved by the others.
    let lambda = solve(&mut k, m);
    for (row, &l) in rows.iter().zip(&lambda) {
        let l = l as Real;
        let dv = row.n * (l * row.q0);
        *v += dv;
        push.add(row.wall, dv, &(x + row.d));
        *c += row.n * (row.q * l).transpose();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::WallFoot;
    use nalgebra::{Matrix2, Vector2};

    fn foot(x: Vector2<Real>, normal: Vector2<Real>, curvature: Real) -> WallFeet<2> {
        let mut feet = WallFeet::default();
        feet.push(WallFoot { curvature, ..WallFoot::still(x, normal, 0) }, 0.0, 1e-12);
        feet
    }

    /// The wall term's weight N(r)/r² grows without bound at the wall (its inverse is zero there)
    /// and vanishes beyond the B-spline support.
    #[test]
    fn wall_weight_is_infinite_on_the_wall_and_zero_beyond_reach() {
        assert_eq!(inverse_wall_weight(0.0), 0.0);
        assert!((inverse_wall_weight(0.5) - 0.25 / 0.5).abs() < 1e-15);
        assert_eq!(inverse_wall_weight(1.5), Real::INFINITY);
    }

    /// A particle on a slip wall keeps its tangential velocity and loses its normal one exactly;
    /// on a sticky wall it takes the wall's (still) velocity.
    #[test]
    fn a_particle_on_the_wall_meets_the_condition_exactly() {
        let h = 0.1;
        let minv = MlsInverse::<2>::regular(h);
        let x = Vector2::new(0.5, 0.2);
        let feet = foot(x, Vector2::new(0.0, -1.0), 0.0);
        for (condition, expect) in
            [(WallCondition::Slip, Vector2::new(0.3, 0.0)), (WallCondition::Sticky, Vector2::zeros())]
        {
            let (mut v, mut c) = (Vector2::new(0.3, -0.7), Matrix2::new(1.0, 2.0, 3.0, 4.0));
            fit_to_walls(&minv, &x, &feet, &[condition.into()], (h, 1e-3), &mut v, &mut c);
            assert!((v - expect).norm() < 1e-12, "{condition:?}: {v}");
        }
    }

    /// A particle that rounding put a depth r past a ceiling (slip), in a fitted field that stretches
    /// normal to the wall (C_nn = 20/s), is carried farther out at r·C_nn when the condition is met at
    /// the foot behind it; once its foot is pinned to it, it is taken back to 1e-9 h inside over the step
    /// (normal velocity −(r + 1e-9 h)/dt) and keeps its tangential velocity.
    #[test]
    fn a_particle_past_a_wall_is_not_carried_farther_out() {
        let (h, depth) = (0.01, 1e-7);
        let minv = MlsInverse::<2>::regular(h);
        let normal = Vector2::new(0.0, 1.0); // into the ceiling at y = 0.8
        let x = Vector2::new(0.5, 0.8 + depth);
        let stretch = Matrix2::new(0.0, 0.0, 0.0, 20.0);
        let mut feet = foot(Vector2::new(0.5, 0.8), normal, 0.0);
        let (mut v, mut c) = (Vector2::new(1.0, 0.0), stretch);
        fit_to_walls(&minv, &x, &feet, &[WallCondition::Slip.into()], (h, 1e-3), &mut v, &mut c);
        assert!((v.dot(&normal) - depth * 20.0).abs() < 1e-6 * depth * 20.0, "at the foot: {v}");
        feet.pin_past(&x, PULL_MARGIN * h);
        let (mut v, mut c) = (Vector2::new(1.0, 0.0), stretch);
        fit_to_walls(&minv, &x, &feet, &[WallCondition::Slip.into()], (h, 1e-3), &mut v, &mut c);
        let back = -(depth + PULL_MARGIN * h) / 1e-3;
        assert!((v.dot(&normal) - back).abs() < 1e-8 * back.abs() && (v.x - 1.0).abs() < 1e-12, "pinned: {v}");
        assert!(x.y + v.y * 1e-3 < 0.8, "inside after the step");
        // Sliding on the ceiling, rounding away from it (a few ulp inside, within the margin): pinned and
        // asked to the margin, so that rounding cannot carry it out next.
        let on = Vector2::new(0.5, 0.8 - 4e-16);
        let mut feet = foot(Vector2::new(0.5, 0.8), normal, 0.0);
        feet.pin_past(&on, PULL_MARGIN * h);
        let (mut v, mut c) = (Vector2::new(1.0, 0.0), stretch);
        fit_to_walls(&minv, &on, &feet, &[WallCondition::Slip.into()], (h, 1e-3), &mut v, &mut c);
        let back = -(PULL_MARGIN * h + (on.y - 0.8)) / 1e-3;
        assert!(on.y < 0.8 && (v.dot(&normal) - back).abs() < 1e-9 * back.abs(), "on the face: {v}");
    }

    /// A particle on a rough separate floor (μ = 0.5) whose fit presses into it at 1 m/s while sliding
    /// at 2 m/s takes the Coulomb update of its fit at its foot: no normal velocity, 1.5 m/s of slide;
    /// one whose fit lifts off keeps it.
    #[test]
    fn a_pressing_particle_on_a_rough_wall_meets_the_friction_cone() {
        let h = 0.01;
        let minv = MlsInverse::<2>::regular(h);
        let normal = Vector2::new(0.0, -1.0); // into the floor at y = 0.2
        let x = Vector2::new(0.5, 0.2);
        let feet = foot(x, normal, 0.0);
        let rough = [WallContact { condition: WallCondition::Separate, friction: 0.5, moving: false }];
        let (mut v, mut c) = (Vector2::new(2.0, -1.0), Matrix2::zeros());
        fit_to_walls(&minv, &x, &feet, &rough, (h, 1e-3), &mut v, &mut c);
        assert!((v - Vector2::new(1.5, 0.0)).norm() < 1e-12, "pressing: {v}");
        let (mut v, mut c) = (Vector2::new(2.0, 0.5), Matrix2::zeros());
        fit_to_walls(&minv, &x, &feet, &rough, (h, 1e-3), &mut v, &mut c);
        assert_eq!(v, Vector2::new(2.0, 0.5), "lifting off");
    }

    /// A particle past both faces of a sticky corner, both feet pinned to it, takes the wall's velocity
    /// (zero) and the one velocity that takes it back 1e-9 h inside both faces over the step: the two
    /// faces' identical rows are solved together, not dropped.
    #[test]
    fn a_particle_past_a_sticky_corner_takes_the_wall_velocity() {
        let h = 0.01;
        let minv = MlsInverse::<2>::regular(h);
        let x = Vector2::new(0.5 + 1e-7, 0.5 + 1e-7);
        let mut feet = WallFeet::default();
        for (foot, normal) in
            [(Vector2::new(0.5, x.y), Vector2::new(1.0, 0.0)), (Vector2::new(x.x, 0.5), Vector2::new(0.0, 1.0))]
        {
            let foot = WallFoot::still(foot, normal, 0);
            feet.push(foot, 1e-7, 1e-12);
        }
        feet.pin_past(&x, PULL_MARGIN * h);
        let (mut v, mut c) = (Vector2::new(0.3, -0.7), Matrix2::new(1.0, 2.0, 3.0, 4.0));
        fit_to_walls(&minv, &x, &feet, &[WallCondition::Sticky.into()], (h, 1e-3), &mut v, &mut c);
        let back = -(1e-7 + PULL_MARGIN * h) / 1e-3;
        assert!((v - Vector2::new(back, back)).norm() < 1e-8 * back.abs(), "{v}");
        let end = x + v * 1e-3;
        assert!(end.x < 0.5 && end.y < 0.5 && (end.x - (0.5 - PULL_MARGIN * h)).abs() < 1e-14, "{end}");
    }

    /// Inside a circular container of radius R, a particle on the slip wall moving along it at
    /// speed U gets the inward normal velocity that keeps it on the wall over a straight step:
    /// |x + dt v − c| = R (to rounding), where without the correction it would end U²dt²/2R out.
    #[test]
    fn curved_walls_keep_the_particle_s_distance_over_a_step() {
        let (h, dt, radius, u) = (0.02, 2e-3, 0.3, 1.5);
        let minv = MlsInverse::<2>::regular(h);
        let centre = Vector2::new(0.5, 0.5);
        let x = centre + Vector2::new(radius, 0.0);
        let feet = foot(centre + Vector2::new(radius, 0.0), Vector2::new(1.0, 0.0), 1.0 / radius);
        let (mut v, mut c) = (Vector2::new(0.0, u), Matrix2::zeros());
        fit_to_walls(&minv, &x, &feet, &[WallCondition::Slip.into()], (h, dt), &mut v, &mut c);
        let moved = (x + v * dt - centre).norm();
        assert!((moved - (x - centre).norm()).abs() < 1e-12, "{moved}");
        assert!((v.y - u).abs() < 1e-12 && v.x < 0.0);
    }
}
