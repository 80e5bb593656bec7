//! The stages of one explicit MLS-MPM step, each a pure function over arrays.
//!
//! Transfers are written with the MLS shape functions of [`MlsInverse`]
//! (`phi` for values, `g` for gradients and forces, eq. (4)–(6) of Toyota &
//! Umetani 2024); on the regular grid they reduce to APIC MLS-MPM (Hu et al. 2018).

use crate::augmented::{AugmentedGrid, NearPoints};
use crate::grid::{GridLayout, GridState};
use crate::kernel::{MlsInverse, Stencil};
use crate::material::{ConstitutiveModel, Material, MaterialPoint};
use crate::math::{Dim, DimOps, Matrix, Real, Vector};
use crate::particles::Particles;
use rayon::prelude::*;

/// Particle index whose stencil left the grid.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OutOfGrid(pub usize);

#[inline]
fn stencil_of<const D: usize>(
    layout: &GridLayout<D>,
    x: &Vector<D>,
    p: usize,
) -> Result<(Stencil<D>, usize), OutOfGrid> {
    let s = Stencil::new(x, 1.0 / layout.h);
    layout.stencil_origin(&s.base).map(|o| (s, o)).ok_or(OutOfGrid(p))
}

/// Scatters particle masses to the regular grid with the B-spline weights
/// (never an augmented grid: density has no boundary condition).
pub fn scatter_mass<const D: usize>(
    layout: &GridLayout<D>,
    x: &[Vector<D>],
    mass: &[Real],
    grid_mass: &mut [Real],
) -> Result<(), OutOfGrid> {
    grid_mass.fill(0.0);
    for (p, (xp, mp)) in x.iter().zip(mass).enumerate() {
        let (s, origin) = stencil_of(layout, xp, p)?;
        s.for_each(layout.h, |o, w, _| grid_mass[origin + layout.offset(&o)] += w * mp);
    }
    Ok(())
}

/// Gathers the density of each particle, ρ_p = Σ_i w_ip m_i / h^D.
///
/// With `wall_fraction` (the part f_i of each node's B-spline support that lies inside the
/// material region, see [`wall_fractions`]), node densities are `m_i / (h^D f_i)`, nodes with
/// f_i < [`MIN_WALL_FRACTION`] are skipped and the weights renormalized: a fluid at rest density
/// next to a wall then reads ρ0 instead of the truncated kernel's ~0.9 ρ0.
pub fn gather_density<const D: usize>(
    layout: &GridLayout<D>,
    x: &[Vector<D>],
    grid_mass: &[Real],
    wall_fraction: Option<&[Real]>,
    density: &mut [Real],
) {
    let inv_cell_volume = layout.h.powi(-(D as i32));
    density.par_iter_mut().zip(x.par_iter()).for_each(|(rho, xp)| {
        let s = Stencil::new(xp, 1.0 / layout.h);
        // Stencils were checked by scatter_mass on the same positions.
        let origin = layout.stencil_origin(&s.base).expect("stencil checked by scatter_mass");
        let (mut sum, mut weight) = (0.0, 0.0);
        s.for_each(layout.h, |o, w, _| {
            let i = origin + layout.offset(&o);
            match wall_fraction {
                None => sum += w * grid_mass[i],
                Some(f) if f[i] >= MIN_WALL_FRACTION => {
                    sum += w * grid_mass[i] / f[i];
                    weight += w;
                }
                Some(_) => {}
            }
        });
        *rho = match wall_fraction {
            None => sum * inv_cell_volume,
            Some(_) if weight > 0.0 => sum / weight * inv_cell_volume,
            Some(_) => 0.0,
        };
    });
}

/// Nodes whose support lies less than this much inside the material are left out of the density.
pub const MIN_WALL_FRACTION: Real = 0.3;

/// The fraction of each node's B-spline support inside `region`: ∫ w_i χ dx / h^D, by
/// sampling the support at h/8 (1 far inside, 0 far outside; computed once, walls are still).
pub fn wall_fractions<const D: usize>(layout: &GridLayout<D>, region: &dyn crate::geometry::Region<D>) -> Vec<Real> {
    const SUB: usize = 8;
    let h = layout.h;
    let per_axis = 3 * SUB;
    let total = per_axis.pow(D as u32);
    (0..layout.num_nodes())
        .into_par_iter()
        .map(|i| {
            let xi = layout.position(i);
            let d = region.distance(&xi).distance;
            if d < -2.0 * h {
                return 1.0;
            }
            if d > 2.0 * h {
                return 0.0;
            }
            let mut inside = 0.0;
            for k in 0..total {
                let mut r = k;
                let mut offset = Vector::<D>::zeros();
                for a in 0..D {
                    offset[a] = ((r % per_axis) as Real + 0.5) / SUB as Real - 1.5;
                    r /= per_axis;
                }
                if region.distance(&(xi + offset * h)).distance < 0.0 {
                    inside += offset.iter().map(|&u| crate::kernel::bspline(u)).product::<Real>();
                }
            }
            inside / (SUB as Real).powi(D as i32)
        })
        .collect()
}

/// Computes `V_p σ_p` of every particle with its material.
pub fn compute_stress<const D: usize>(
    materials: &[Material],
    particles: &Particles<D>,
    density: &[Real],
    stress: &mut [Matrix<D>],
) where
    Dim<D>: DimOps<D>,
{
    stress.par_iter_mut().enumerate().for_each(|(p, out)| {
        let point = MaterialPoint {
            f: particles.f[p],
            jp: particles.jp[p],
            grad_v: particles.c[p],
            mass: particles.mass[p],
            vol0: particles.vol0[p],
            density: density[p],
        };
        *out = materials[particles.material[p] as usize].volume_stress(&point);
    });
}

/// The grid points a particle interpolates from (regular nodes, and boundary
/// points on an augmented grid) and the inverse of its MLS moment matrix.
pub trait Neighbourhood<const D: usize>: Sync {
    /// Calls `f(point, w, x_point − x_p)` for every grid point of particle `p` at `x`.
    fn for_each(&self, p: usize, x: &Vector<D>, f: impl FnMut(usize, Real, Vector<D>)) -> Result<(), OutOfGrid>;
    /// `M_p⁻¹` of particle `p` (eq. (5)).
    fn inverse(&self, p: usize) -> MlsInverse<D>;
}

/// The whole 3^D stencil with the closed-form inverse: MLS-MPM on the regular grid.
pub struct RegularStencil<'a, const D: usize> {
    pub layout: &'a GridLayout<D>,
    pub minv: MlsInverse<D>,
}

impl<const D: usize> Neighbourhood<D> for RegularStencil<'_, D> {
    #[inline]
    fn for_each(&self, p: usize, x: &Vector<D>, mut f: impl FnMut(usize, Real, Vector<D>)) -> Result<(), OutOfGrid> {
        let (s, origin) = stencil_of(self.layout, x, p)?;
        s.for_each(self.layout.h, |o, w, d| f(origin + self.layout.offset(&o), w, d));
        Ok(())
    }
    #[inline]
    fn inverse(&self, _p: usize) -> MlsInverse<D> {
        self.minv
    }
}

/// Included nodes and boundary points of the augmented grid, with per-particle inverses.
pub struct AugmentedStencil<'a, const D: usize> {
    pub layout: &'a GridLayout<D>,
    pub grid: &'a AugmentedGrid<D>,
    pub minv: &'a [MlsInverse<D>],
    pub near: &'a [NearPoints],
}

impl<const D: usize> Neighbourhood<D> for AugmentedStencil<'_, D> {
    #[inline]
    fn for_each(&self, p: usize, x: &Vector<D>, f: impl FnMut(usize, Real, Vector<D>)) -> Result<(), OutOfGrid> {
        self.grid.for_each_cached(self.layout, x, p, &self.near[p], f)
    }
    #[inline]
    fn inverse(&self, p: usize) -> MlsInverse<D> {
        self.minv[p]
    }
}

/// Particle→grid transfer of mass and momentum with the stress term:
/// `m_i += φ m_p`, `(mv)_i += φ m_p (v_p + C_p (x_i − x_p)) − dt V_p σ_p g` (eq. (6)),
/// and the B-spline mass `Σ w m_p` that [`grid_velocity`] compares against.
/// Serial, in particle order, so the sums are reproducible.
pub fn p2g<const D: usize>(
    nbh: &impl Neighbourhood<D>,
    particles: &Particles<D>,
    stress: &[Matrix<D>],
    dt: Real,
    grid: &mut GridState<D>,
) -> Result<(), OutOfGrid> {
    grid.clear();
    for p in 0..particles.len() {
        let minv = nbh.inverse(p);
        let mp = particles.mass[p];
        let (vp, cp, force) = (particles.v[p], particles.c[p], stress[p] * dt);
        nbh.for_each(p, &particles.x[p], |i, w, dpos| {
            let (phi, g) = minv.shape(w, &dpos);
            grid.mass[i] += phi * mp;
            grid.spline_mass[i] += w * mp;
            grid.momentum[i] += (vp + cp * dpos) * (phi * mp) - force * g;
        })?;
    }
    Ok(())
}

/// A node whose MLS mass `Σ φ m_p` is below this fraction of its B-spline mass `Σ w m_p`
/// divides its momentum by that fraction of the B-spline mass instead. Near walls φ = w(α + β·d)
/// can vanish or turn negative while the force weight g = w(β + Γd) does not, so a node could get
/// a finite force on a vanishing mass; with the floor its acceleration stays within 1/fraction of
/// what the B-spline weights would give (on the regular grid φ = w and nothing changes).
pub const LOW_MASS_FRACTION: Real = 0.5;

/// Grid update: momentum → velocity, then gravity `g` (m/s²) over `dt` (s).
/// Nodes without mass get zero velocity. Returns the number of low-mass nodes.
pub fn grid_velocity<const D: usize>(grid: &mut GridState<D>, gravity: &Vector<D>, dt: Real) -> usize {
    let dv = gravity * dt;
    grid.momentum
        .par_iter_mut()
        .zip(grid.mass.par_iter())
        .zip(grid.spline_mass.par_iter())
        .map(|((mv, &m), &spline)| {
            if spline <= 0.0 {
                *mv = Vector::<D>::zeros();
                return 0;
            }
            let floor = LOW_MASS_FRACTION * spline;
            *mv = *mv / m.max(floor) + dv;
            usize::from(m < floor)
        })
        .sum()
}

/// Grid→particle transfer: `v_p = Σ φ v_i`, `C_p = Σ v_i gᵀ` (eq. (4)).
pub fn g2p<const D: usize>(
    nbh: &impl Neighbourhood<D>,
    velocity: &[Vector<D>],
    x: &[Vector<D>],
    v: &mut [Vector<D>],
    c: &mut [Matrix<D>],
) {
    v.par_iter_mut().zip(c.par_iter_mut()).zip(x.par_iter()).enumerate().for_each(|(p, ((vp, cp), xp))| {
        let minv = nbh.inverse(p);
        let mut vn = Vector::<D>::zeros();
        let mut cn = Matrix::<D>::zeros();
        // Every particle's points were checked by p2g on the same positions.
        let _ = nbh.for_each(p, xp, |i, w, dpos| {
            let vi = velocity[i];
            let (phi, g) = minv.shape(w, &dpos);
            vn += vi * phi;
            cn += vi * g.transpose();
        });
        *vp = vn;
        *cp = cn;
    });
}

/// A particle that has crossed a wall (its MLS fit then extrapolates, and left alone it can run
/// away) loses the part of its velocity that would carry it deeper, `v −= n·max(v·n, 0)`, whatever
/// the wall's condition; moving back out is free. Only particles near walls (`near[p]`) are
/// checked. Returns how many were held.
pub fn hold_at_walls<const D: usize>(
    region: &dyn crate::geometry::Region<D>,
    near: &[bool],
    x: &[Vector<D>],
    v: &mut [Vector<D>],
) -> usize {
    v.par_iter_mut()
        .zip(x.par_iter())
        .zip(near.par_iter())
        .map(|((vp, xp), &near)| {
            if !near {
                return 0;
            }
            let d = region.distance(xp);
            let into = vp.dot(&d.normal);
            if d.distance > 0.0 && into > 0.0 {
                *vp -= d.normal * into;
                1
            } else {
                0
            }
        })
        .sum()
}

/// Advection `x += dt v` and the deformation update of each material.
pub fn advect<const D: usize>(materials: &[Material], particles: &mut Particles<D>, dt: Real)
where
    Dim<D>: DimOps<D>,
{
    let Particles { x, v, c, f, jp, material, .. } = particles;
    x.par_iter_mut()
        .zip(v.par_iter())
        .zip(c.par_iter())
        .zip(f.par_iter_mut())
        .zip(jp.par_iter_mut())
        .zip(material.par_iter())
        .for_each(|(((((xp, vp), cp), fp), jpp), m)| {
            *xp += vp * dt;
            materials[*m as usize].update_deformation(fp, jpp, cp, dt);
        });
}

/// The first particle whose state is not finite, if any.
pub fn first_non_finite<const D: usize>(particles: &Particles<D>) -> Option<usize> {
    (0..particles.len()).into_par_iter().find_first(|&p| {
        !(particles.x[p].iter().all(|a| a.is_finite())
            && particles.v[p].iter().all(|a| a.is_finite())
            && particles.f[p].iter().all(|a| a.is_finite()))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix2, Vector2};

    fn random_particles(n: usize) -> Particles<2> {
        let mut ps = Particles::<2>::default();
        let mut s = 12345u64;
        let mut rnd = || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..n {
            let x = Vector2::new(0.3 + 0.4 * rnd(), 0.3 + 0.4 * rnd());
            let v = Vector2::new(rnd() - 0.5, rnd() - 0.5);
            let m = 0.5 + rnd();
            ps.push(x, v, m, 1.0, 0, 0);
            let last = ps.len() - 1;
            ps.c[last] = Matrix2::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5, rnd() - 0.5);
        }
        ps
    }

    fn angular_momentum(x: &[Vector2<f64>], v: &[Vector2<f64>], m: &[f64], c: &[Matrix2<f64>], h: f64) -> f64 {
        // Particle angular momentum including the APIC affine part: Σ m (x × v) + m h²/4 (C₁₀ − C₀₁).
        x.iter()
            .zip(v)
            .zip(m)
            .zip(c)
            .map(|(((x, v), m), c)| m * (x.perp(v) + h * h / 4.0 * (c[(1, 0)] - c[(0, 1)])))
            .sum()
    }

    /// With no walls and no stress, P2G → G2P conserves mass, linear and angular momentum to round-off.
    #[test]
    fn transfers_conserve_mass_and_momentum() {
        let h = 0.05;
        let layout = GridLayout::<2>::new(h, [20, 20]);
        let mut ps = random_particles(300);
        let stress = vec![Matrix2::zeros(); ps.len()];
        let nbh = RegularStencil { layout: &layout, minv: MlsInverse::regular(h) };
        let mut grid = GridState::new(layout.num_nodes());
        p2g(&nbh, &ps, &stress, 1e-3, &mut grid).unwrap();

        let mass: f64 = ps.mass.iter().sum();
        let p_particles = ps.momentum();
        let l_particles = angular_momentum(&ps.x, &ps.v, &ps.mass, &ps.c, h);
        let grid_mass: f64 = grid.mass.iter().sum();
        let p_grid = grid.momentum.iter().fold(Vector2::zeros(), |a, b| a + b);
        let l_grid: f64 = (0..layout.num_nodes()).map(|i| layout.position(i).perp(&grid.momentum[i])).sum();
        assert!((grid_mass - mass).abs() < 1e-12 * mass);
        assert!((p_grid - p_particles).norm() < 1e-12 * mass);
        assert!((l_grid - l_particles).abs() < 1e-12 * mass, "{l_grid} vs {l_particles}");

        grid_velocity(&mut grid, &Vector2::zeros(), 1e-3);
        let (x, mut v, mut c) = (ps.x.clone(), ps.v.clone(), ps.c.clone());
        g2p(&nbh, &grid.momentum, &x, &mut v, &mut c);
        ps.v = v;
        ps.c = c;
        let p_back = ps.momentum();
        let l_back = angular_momentum(&ps.x, &ps.v, &ps.mass, &ps.c, h);
        assert!((p_back - p_particles).norm() < 1e-12 * mass, "{p_back} vs {p_particles}");
        assert!((l_back - l_particles).abs() < 1e-12 * mass, "{l_back} vs {l_particles}");
    }

    /// A node whose MLS mass falls below half its B-spline mass divides by that half: a vanishing
    /// mass cannot turn a finite force into a runaway velocity, and the node is counted.
    #[test]
    fn low_mass_nodes_are_bounded_and_counted() {
        let mut grid = GridState::<2> {
            mass: vec![1.0, 0.1, -0.2, 0.0],
            spline_mass: vec![1.0, 1.0, 1.0, 0.0],
            momentum: vec![
                Vector2::new(2.0, 0.0),
                Vector2::new(0.3, 0.0),
                Vector2::new(-0.4, 0.0),
                Vector2::new(5.0, 0.0),
            ],
        };
        let low = grid_velocity(&mut grid, &Vector2::zeros(), 1e-3);
        assert_eq!(low, 2);
        assert_eq!(grid.momentum[0], Vector2::new(2.0, 0.0));
        assert!((grid.momentum[1] - Vector2::new(0.6, 0.0)).norm() < 1e-15);
        assert!((grid.momentum[2] - Vector2::new(-0.8, 0.0)).norm() < 1e-15);
        assert_eq!(grid.momentum[3], Vector2::zeros());
    }

    /// Next to a wall the truncated kernel reads a uniform fluid of density 1 about 25% light; with the
    /// wall fractions it reads 1 within 4% (the particles' h/4 lattice and the h/8 sampling of the
    /// fractions are two quadratures of the same cut kernel, a few percent apart at the cut).
    #[test]
    fn wall_fractions_restore_density_next_to_a_wall() {
        use crate::geometry::{Point, Polygon, WallShape, Walls2};
        let h = 1.0 / 32.0;
        let layout = GridLayout::<2>::new(h, [32, 32]);
        let floor = 0.3 + 0.3 * h;
        let walls = Walls2::new(
            vec![WallShape::Polygon(Polygon::new(vec![
                Point::new(0.0, floor),
                Point::new(1.0, floor),
                Point::new(1.0, 1.0),
                Point::new(0.0, 1.0),
            ]))],
            Point::new(1.0, 1.0),
        );
        let fractions = wall_fractions(&layout, &walls);
        // A uniform fluid of density 1 on a fine lattice above the floor.
        let spacing = h / 4.0;
        let (mut x, mut mass) = (Vec::new(), Vec::new());
        for j in 0..200 {
            for i in 0..200 {
                let p = Point::new(0.25 + (i as f64 + 0.5) * spacing, floor + (j as f64 + 0.5) * spacing);
                if p.y < 0.9 && p.x < 0.75 {
                    x.push(p);
                    mass.push(spacing * spacing);
                }
            }
        }
        let mut grid_mass = vec![0.0; layout.num_nodes()];
        scatter_mass(&layout, &x, &mass, &mut grid_mass).unwrap();
        let probe = vec![Point::new(0.5, floor + 0.2 * h)];
        let (mut plain, mut corrected) = (vec![0.0], vec![0.0]);
        gather_density(&layout, &probe, &grid_mass, None, &mut plain);
        gather_density(&layout, &probe, &grid_mass, Some(&fractions), &mut corrected);
        assert!(plain[0] < 0.8, "truncated kernel: {}", plain[0]);
        assert!((corrected[0] - 1.0).abs() < 0.04, "corrected: {}", corrected[0]);
    }

    /// A particle past a wall keeps its motion along the wall and back out, but not deeper in;
    /// particles inside, or not flagged as near a wall, are untouched.
    #[test]
    fn particles_past_a_wall_are_held() {
        use crate::geometry::{Point, Walls2};
        let walls = Walls2::new(vec![], Point::new(1.0, 1.0)); // the domain box alone
        let x = vec![Point::new(0.5, -0.01), Point::new(0.5, -0.01), Point::new(0.5, 0.2), Point::new(0.5, -0.01)];
        let mut v = vec![Point::new(1.0, -2.0), Point::new(1.0, 2.0), Point::new(1.0, -2.0), Point::new(1.0, -2.0)];
        let held = hold_at_walls(&walls, &[true, true, true, false], &x, &mut v);
        assert_eq!(held, 1);
        assert_eq!(v, vec![Point::new(1.0, 0.0), Point::new(1.0, 2.0), Point::new(1.0, -2.0), Point::new(1.0, -2.0)]);
    }

    /// A particle whose stencil leaves the grid is reported by index, not indexed out of bounds.
    #[test]
    fn out_of_grid_is_reported() {
        let layout = GridLayout::<2>::new(0.1, [4, 4]);
        let mut ps = random_particles(3);
        ps.x[1] = Vector2::new(-0.5, 0.2);
        let mut mass = vec![0.0; layout.num_nodes()];
        assert_eq!(scatter_mass(&layout, &ps.x, &ps.mass, &mut mass), Err(OutOfGrid(1)));
    }
}
