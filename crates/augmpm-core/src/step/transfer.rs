//! The stages of one explicit MLS-MPM step, each a function over arrays.
//!
//! Transfers are written with the MLS shape functions of [`crate::kernel::MlsInverse`]
//! (`phi` for values, `g` for gradients and forces, eq. (4)–(6) of Toyota &
//! Umetani 2024); on the regular grid they reduce to APIC MLS-MPM (Hu et al. 2018).
//! Particle→grid stages scatter through a [`Schedule`] (coloured blocks, no atomics,
//! bitwise reproducible for any thread count); grid→particle stages are per particle.

use crate::geometry::{Region, MIN_WALL_FRACTION};
use crate::grid::{GridLayout, GridState};
use crate::kernel::Stencil;
use crate::material::{ConstitutiveModel, Material, MaterialPoint};
use crate::math::{Dim, DimOps, Matrix, Real, Vector};
use crate::parallel::{prefetch, task_len, Disjoint, MIN_BLOCKS};
use crate::particles::Particles;
use crate::step::packing::{self, Packing};
use crate::step::schedule::{stencil_in_grid, Reach, Schedule};
use crate::step::tile::{with_tile, Tile};
use crate::treatment::augmented::{AugmentedGrid, AugmentedTransfer, WallEntry, WallParticles};
use crate::treatment::wall_fit::WallPush;
use rayon::prelude::*;

/// Scatters particle masses to the regular grid with the B-spline weights (never an augmented
/// grid: density has no boundary condition). `grid_mass` must be zero on the schedule's active
/// blocks; the particles must have been sorted by `schedule` at these positions.
pub fn scatter_mass<const D: usize>(
    layout: &GridLayout<D>,
    schedule: &Schedule<D>,
    x: &[Vector<D>],
    mass: &[Real],
    grid_mass: &mut [Real],
) {
    let out = Disjoint::new(grid_mass);
    let inv_h = 1.0 / layout.h;
    schedule.for_each_block(|reach, block| {
        for (k, &p) in block.iter().enumerate() {
            if let Some(&ahead) = block.get(k + PREFETCH_AHEAD) {
                prefetch(x, ahead as usize);
                prefetch(mass, ahead as usize);
            }
            let (s, origin) = stencil(layout, &x[p as usize], inv_h);
            reach.check(&s.base);
            let mp = mass[p as usize];
            assert!(last_node(layout, origin) < out.len());
            // SAFETY: in bounds (the stencil's last node is, checked above); blocks scattered together
            // never share a node (see `schedule`).
            s.for_each_index(layout.h, origin, layout.strides(), |i, w, _| unsafe {
                out.update_unchecked(i, |m| *m += w * mp)
            });
        }
    });
}

/// Per node, the J-bar sums of the particles that smooth their J, which [`p2g`] scatters: their rest
/// volume `Σ_p w_ip V⁰_p` and volume `Σ_p w_ip V⁰_p J_p` (`V⁰ J` is a particle's volume).
/// [`VolumeRatio::finish`] divides the second by the first: the node's J. [`g2p`] gathers it back,
/// `J̄_p = Σ_i w_ip J_i` ([`volume_ratio_at`]), as the J-bar methods of MPM do, and advances that.
/// Empty when no material smooths its J.
#[derive(Clone, Debug, Default)]
pub struct VolumeRatio {
    /// Per node, the two sums side by side (one cache line for P2G's two updates). Two arrays of their
    /// own, so that G2P reads only the ratios, were measured with the sums scattered in the momentum's
    /// loop: G2P no faster, P2G slower. After [`VolumeRatio::finish`], the second is the node's J.
    pub nodes: Vec<(Real, Real)>,
}

impl VolumeRatio {
    /// Zero sums on `nodes` grid nodes.
    pub fn new(nodes: usize) -> Self {
        Self { nodes: vec![(0.0, 0.0); nodes] }
    }

    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// Zeroes the sums on the node `blocks` of `schedule`.
    pub fn clear<const D: usize>(&mut self, layout: &GridLayout<D>, schedule: &Schedule<D>, blocks: &[u32]) {
        schedule.clear(layout, blocks, &mut self.nodes, (0.0, 0.0));
    }

    /// Zeroes every sum.
    pub fn fill_zero(&mut self) {
        self.nodes.fill((0.0, 0.0));
    }

    pub fn heap_bytes(&self) -> usize {
        crate::math::heap_bytes(&self.nodes)
    }

    /// The nodes' J, `Σ_p w_ip V⁰_p J_p / Σ_p w_ip V⁰_p`, on the schedule's active blocks (in the grid
    /// stage, after P2G); a node without volume keeps 0.
    pub fn finish<const D: usize>(&mut self, layout: &GridLayout<D>, schedule: &Schedule<D>) {
        let out = Disjoint::new(&mut self.nodes);
        // SAFETY: node blocks do not overlap, and each active block is listed once.
        schedule.for_each_node_of(layout, schedule.active(), |i| unsafe {
            out.update(i, |g| {
                if g.0 > 0.0 {
                    g.1 /= g.0;
                }
            })
        });
    }
}

/// The smoothed volume ratio of a particle: `Σ_i w_ip J_i` with `J_i = Σ_q w_iq V⁰_q J_q / Σ_q w_iq V⁰_q`
/// from [`VolumeRatio`]. The sub-cell part of J, which no grid force can see or
/// correct, is removed; `Σ_p V⁰_p J_p` (the total volume) is kept exactly, and the averages are
/// normalised, so a free surface or a wall does not bias them. Every node of the stencil with a weight
/// has mass: the particle itself put `w` there.
#[inline]
pub fn volume_ratio_at<const D: usize>(
    layout: &GridLayout<D>,
    s: &Stencil<D>,
    origin: usize,
    ratio: &VolumeRatio,
) -> Real {
    let (mut sum, nodes) = (0.0, &ratio.nodes[..]);
    assert!(last_node(layout, origin) < nodes.len());
    // SAFETY: i ≤ the stencil's last node, in bounds (checked above).
    s.for_each_index(layout.h, origin, layout.strides(), |i, w, _| sum += w * unsafe { nodes.get_unchecked(i) }.1);
    sum
}

/// Index of the last node (offset `[2; D]`) of the stencil whose first node is `origin`: every node of
/// the stencil is at or below it, so one bounds check covers all 3^D.
#[inline(always)]
fn last_node<const D: usize>(layout: &GridLayout<D>, origin: usize) -> usize {
    origin + layout.offset(&[2; D])
}

/// Stencil of a particle the schedule has sorted (so its stencil is inside the grid).
#[inline(always)]
fn stencil<const D: usize>(layout: &GridLayout<D>, x: &Vector<D>, inv_h: Real) -> (Stencil<D>, usize) {
    let s = Stencil::new(x, inv_h);
    let origin = layout.stencil_origin(&s.base).expect("particles were sorted into the grid this step");
    (s, origin)
}

/// The density of a particle at `x`, ρ_p = Σ_i w_ip m_i / h^D.
///
/// With `wall_fraction` (the part f_i of each node's B-spline support that lies inside the
/// material region, see [`wall_fractions`]), node densities are `m_i / (h^D f_i)`, nodes with
/// f_i < [`MIN_WALL_FRACTION`] are skipped and the weights renormalized: a fluid at rest density
/// next to a wall then reads ρ0 instead of the truncated kernel's ~0.9 ρ0.
#[inline]
pub fn density_at<const D: usize>(
    layout: &GridLayout<D>,
    s: &Stencil<D>,
    origin: usize,
    grid_mass: &[Real],
    wall_fraction: Option<&[Real]>,
) -> Real {
    let inv_cell_volume = layout.h.powi(-(D as i32));
    let (mut sum, mut weight) = (0.0, 0.0);
    match wall_fraction {
        None => {
            assert!(last_node(layout, origin) < grid_mass.len());
            // SAFETY: i ≤ the stencil's last node, in bounds (checked above).
            s.for_each_index(layout.h, origin, layout.strides(), |i, w, _| {
                sum += w * unsafe { grid_mass.get_unchecked(i) }
            });
            sum * inv_cell_volume
        }
        Some(f) => {
            s.for_each_index(layout.h, origin, layout.strides(), |i, w, _| {
                if f[i] >= MIN_WALL_FRACTION {
                    sum += w * grid_mass[i] / f[i];
                    weight += w;
                }
            });
            if weight > 0.0 {
                sum / weight * inv_cell_volume
            } else {
                0.0
            }
        }
    }
}

/// The fraction of each node's B-spline support inside `region`: ∫ w_i χ dx / h^D, by
/// sampling the support at h/8 (1 far inside, 0 far outside; computed once, walls are still).
pub fn wall_fractions<const D: usize>(layout: &GridLayout<D>, region: &dyn Region<D>) -> Vec<Real> {
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

/// Where a step's transfers run: the grid, the particle schedule and, on an augmented grid,
/// the boundary points and the particles whose MLS systems see them.
#[derive(Clone, Copy)]
pub struct Transfer<'a, const D: usize> {
    pub layout: &'a GridLayout<D>,
    pub schedule: &'a Schedule<D>,
    pub augmented: Option<(&'a AugmentedGrid<D>, &'a WallParticles<D>)>,
}

/// The grid density input of P2G (fluids with `density_estimate = "grid"`): the B-spline grid mass of
/// [`scatter_mass`] with, optionally, the nodes' wall fractions.
#[derive(Clone, Copy)]
pub struct GridDensity<'a> {
    pub grid_mass: &'a [Real],
    pub wall_fraction: Option<&'a [Real]>,
}

/// How many particles ahead the scatters, which visit the particles block by block ([`p2g`], [`scatter_mass`]),
/// ask for a particle's data ([`prefetch`]). Once the particles have mixed, a block's particles lie at
/// scattered indices and each of their arrays is a cache miss: on the 256² dam break after 2,000 steps
/// (one thread, `benches/compare_builds.py --warm-up 2000`), P2G took 0.70× its time without (median of
/// 60 rounds; 0.86× fastest round to fastest round), the step 0.81× (0.92×); bitwise the same.
const PREFETCH_AHEAD: usize = 4;

/// Asks for the arrays P2G reads of particle `p` ([`prefetch`]).
#[inline(always)]
fn prefetch_particle<const D: usize>(particles: &Particles<D>, p: usize) {
    prefetch(&particles.x, p);
    prefetch(&particles.v, p);
    prefetch(&particles.c, p);
    prefetch(&particles.f, p);
    prefetch(&particles.jp, p);
    prefetch(&particles.mass, p);
    prefetch(&particles.vol0, p);
    prefetch(&particles.body, p);
}

/// Particle→grid transfer of mass and momentum with the stress term. On an augmented grid,
/// for the particles whose MLS system sees a wall:
/// - `transfer = "paper"`: `m_i += φ m_p`, `(mv)_i += φ m_p (v_p + C_p (x_i − x_p)) − dt V_p σ_p g`
///   (eq. (6)), and, of every particle, the B-spline mass `Σ w m_p` that [`grid_velocity`] compares against
///   (`grid` keeps it only for this transfer);
/// - `transfer = "stable"`: mass and momentum with `φ` replaced by the normalised B-spline weight `ŵ = w / Σw`
///   (Σ over the particle's grid points): every mass is positive, mass is conserved, and P2G is
///   the transpose of the G2P fit, so a round trip cannot add kinetic energy.
///
/// The force weight `g` comes from the particle's MLS inverse in both. Each particle's stress
/// `V_p σ_p` is computed here from its material, with the density it sees (gathered from the grid when
/// `grid_density` holds it, or ρ0/J from its own J), which is written to `density`. `grid` must be zero
/// on the schedule's active blocks and on the boundary points.
///
/// The particles that smooth their J also scatter `(V⁰_p, V⁰_p J_p)` with the B-spline weights to
/// `volume_ratio` (zero on the active blocks; empty when no material smooths), in the same pass:
/// [`VolumeRatio::finish`] turns the sums into the nodes' J, which [`g2p`] gathers back. The J-bar
/// average of this step's J is the one advanced, and the stress of the next step sees it. Where a material
/// relaxes its J toward the packing (`packing` not empty), every particle scatters the volume it occupies
/// ([`ConstitutiveModel::occupied_volume`]) to `packing`'s sums, in the same pass.
///
/// Away from walls φ = w and g = 4/h² w (x_i − x_p), and the momentum is `w (m v + A (x_i − x_p))`
/// with one affine matrix `A = m C − 4 dt/h² V σ` per particle (the MLS-MPM form of Hu et al. 2018).
#[allow(clippy::too_many_arguments)]
pub fn p2g<const D: usize>(
    t: &Transfer<'_, D>,
    materials: &[Material],
    particles: &Particles<D>,
    grid_density: Option<GridDensity<'_>>,
    density: &mut [Real],
    dt: Real,
    grid: &mut GridState<D>,
    volume_ratio: &mut VolumeRatio,
    packing: &mut Packing,
) where
    Dim<D>: DimOps<D>,
{
    debug_assert!(keeps_f_for_all(particles, materials), "a material keeps F: it must be kept for every particle");
    let layout = t.layout;
    let packs = !packing.is_empty();
    let (h, inv_h) = (layout.h, 1.0 / layout.h);
    let apic = 4.0 * dt * inv_h * inv_h;
    // The B-spline mass, which only the paper's transfer reads (`grid` keeps it then).
    let track_spline = t.augmented.is_some_and(|(g, _)| g.transfer == AugmentedTransfer::Paper);
    debug_assert!(!track_spline || grid.keeps_spline_mass(), "the paper's transfer needs the B-spline mass");
    let density_out = Disjoint::new(density);
    let smoothing = !volume_ratio.is_empty();
    let out = P2gOut {
        mass: Disjoint::new(&mut grid.mass),
        spline: Disjoint::new(&mut grid.spline_mass),
        momentum: Disjoint::new(&mut grid.momentum),
        volume_ratio: Disjoint::new(&mut volume_ratio.nodes),
        packing: Disjoint::new(&mut packing.nodes),
    };
    // Copies of the arrays' pointers (as in the scatters below), which no grid store can alias.
    let P2gOut { mass, spline, momentum, .. } = out;
    let tiles = through_tiles::<D>(track_spline);
    let p2g_block = |reach: &Reach<D>, block: &[u32], mut tile: Option<&mut Tile>| {
        for (k, &p) in block.iter().enumerate() {
            if let Some(&ahead) = block.get(k + PREFETCH_AHEAD) {
                prefetch_particle(particles, ahead as usize);
            }
            let p = p as usize;
            let x = particles.x[p];
            let (s, origin) = stencil(layout, &x, inv_h);
            reach.check(&s.base);
            let material = &materials[particles.body[p] as usize];
            let mut rho = 0.0;
            if let Some(g) = grid_density {
                rho = density_at(layout, &s, origin, g.grid_mass, g.wall_fraction);
            }
            // The particle's rest volume and volume, when its J is smoothed.
            let volumes = (smoothing && material.smooths_volume_ratio())
                .then(|| (particles.vol0[p], particles.vol0[p] * particles.jp[p]));
            let point = MaterialPoint {
                f: particles.deformation_gradient(p),
                jp: particles.jp[p],
                grad_v: particles.c[p],
                mass: particles.mass[p],
                vol0: particles.vol0[p],
                density: rho,
            };
            // A fluid's density and stress in one call, the density computed once: P2G 0.976× its time
            // (95% interval of the median 0.965–0.989; 256² dam break, one thread, 40 rounds), bitwise the
            // same. The same as a method of every model, dispatched over the five, took 1.047×.
            let (rho_p, stress) = match material {
                Material::Fluid(fluid) => fluid.density_and_volume_stress(&point),
                _ => (material.current_density(&point), material.volume_stress(&point)),
            };
            // SAFETY (every `update` below): each particle is in one block, and blocks scattered
            // together never share a grid point (see `schedule`).
            unsafe { density_out.update(p, |d| *d = rho_p) };
            if let Some(volumes) = volumes {
                // J is smoothed over the regular grid, near walls too: one loop for every particle, as
                // fast as the same sums fused into the momentum's loop (measured; in 3D a fused loop, with
                // the momentum scattered by rows, took 1.04× the time: not kept).
                // SAFETY: exclusive as stated above.
                unsafe { out.scatter_volume(layout, &s, origin, volumes) };
            }
            // The packing sums of the particle, which the momentum's scatter takes along where it can.
            let mut packing_sums = packs.then(|| {
                let rest = if material.packing_relaxation_time().is_some() { particles.vol0[p] } else { 0.0 };
                [material.occupied_volume(&point, rho_p), rest, rest * particles.jp[p]]
            });
            let (mp, vp, cp) = (particles.mass[p], particles.v[p], particles.c[p]);
            match (t.augmented.and_then(|(g, table)| table.entry(p).map(|e| (g, e))), tile.as_deref_mut()) {
                (None, Some(tile)) => tile.scatter(reach, &s, h, mp, &(vp * mp), &(cp * mp - stress * apic)),
                (None, None) => {
                    let node = RegularNode { mp, mv: vp * mp, affine: cp * mp - stress * apic };
                    // SAFETY: exclusive as stated above.
                    unsafe {
                        if track_spline {
                            out.scatter_regular::<true, false>(layout, &s, origin, &node, [0.0; 3]);
                        } else if let Some(sums) = packing_sums.take() {
                            out.scatter_regular::<false, true>(layout, &s, origin, &node, sums);
                        } else {
                            out.scatter_regular::<false, false>(layout, &s, origin, &node, [0.0; 3]);
                        }
                    }
                }
                (Some((g, entry @ WallEntry { minv, near, total, tilt, .. })), _) => {
                    let mut force = stress * dt;
                    if g.transfer == AugmentedTransfer::Stable && material.keeps_volume_ratio() && point.jp > SEPARATED
                    {
                        force *= lone_particle_stress_scale(minv, total, material, h, dt);
                    }
                    match g.transfer {
                        AugmentedTransfer::Paper => g.for_each_near(layout, &x, near, |i, w, d| {
                            let (phi, grad) = minv.shape(w, &d);
                            unsafe {
                                mass.update(i, |m| *m += phi * mp);
                                spline.update(i, |m| *m += w * mp);
                                momentum.update(i, |m| *m += (vp + cp * d) * (phi * mp) - force * grad);
                            }
                        }),
                        // A particle whose grid points all have zero weight (deep in a wall) gives nothing.
                        AugmentedTransfer::Stable if total <= 0.0 => {}
                        AugmentedTransfer::Stable => {
                            let share = mp / total;
                            // The spin the particle carries (APIC's, over the regular second moment) over
                            // its own grid points' second moment: the grid gets its angular momentum.
                            let cp = entry.affine_velocity::<Dim<D>>(&cp, h);
                            g.for_each_near_tilted(layout, &x, near, &tilt, |i, w, d| {
                                let (_, grad) = minv.shape(w, &d);
                                let m_i = w * share;
                                unsafe {
                                    mass.update(i, |m| *m += m_i);
                                    momentum.update(i, |m| *m += (vp + cp * d) * m_i - force * grad);
                                }
                            })
                        }
                    }
                }
            }
            if let Some(sums) = packing_sums {
                // SAFETY: exclusive as stated above.
                unsafe { out.scatter_packing(layout, &s, origin, sums) };
            }
        }
    };
    t.schedule.for_each_block(|reach, block| {
        if tiles {
            with_tile(|tile| {
                tile.begin();
                p2g_block(reach, block, Some(tile));
                // SAFETY: the blocks scattered together never share a grid point (see `schedule`).
                unsafe { tile.add_to_grid(layout, reach, mass, momentum) };
            });
        } else {
            p2g_block(reach, block, None);
        }
    });
}

/// Whether P2G scatters the particles away from walls into a tile per block ([`super::tile`]): in 3D f32,
/// unless the paper's transfer needs the B-spline mass (`track_spline`), which the tile does not hold. f64
/// and 2D scatter straight into the grid (measured: the tile took 1.16× P2G's time in 3D f64, 1.19× in 2D).
/// This crate's tests run in f64 and turn the tiles on with `tests::TILES`.
#[inline(always)]
fn through_tiles<const D: usize>(track_spline: bool) -> bool {
    #[cfg(test)]
    let in_tests = tests::TILES.with(|t| t.get());
    #[cfg(not(test))]
    let in_tests = false;
    D == 3 && !track_spline && (cfg!(feature = "f32") || in_tests)
}

/// The grid arrays P2G writes, each shared by the blocks scattered together (which never share a node).
struct P2gOut<'a, const D: usize> {
    mass: Disjoint<'a, Real>,
    spline: Disjoint<'a, Real>,
    momentum: Disjoint<'a, Vector<D>>,
    volume_ratio: Disjoint<'a, (Real, Real)>,
    packing: Disjoint<'a, [Real; 6]>,
}

/// What a particle away from walls gives each node of its stencil: with the weight w and `d = x_i − x_p`,
/// mass `w m_p` and momentum `w (m_p v_p + A_p d)`.
struct RegularNode<const D: usize> {
    mp: Real,
    mv: Vector<D>,
    affine: Matrix<D>,
}

impl<const D: usize> P2gOut<'_, D> {
    /// Scatters a particle's [`RegularNode`] over its stencil, to the B-spline mass too with `SPLINE`, and with
    /// `PACK` its packing sums `packing_sums` as [`Self::scatter_packing`] does, in the same walk (the branches
    /// taken once a particle, not a node).
    ///
    /// # Safety
    /// No other thread writes the stencil's nodes meanwhile.
    #[inline(always)]
    unsafe fn scatter_regular<const SPLINE: bool, const PACK: bool>(
        &self,
        layout: &GridLayout<D>,
        s: &Stencil<D>,
        origin: usize,
        node: &RegularNode<D>,
        packing_sums: [Real; 3],
    ) {
        // The pointers copied: read through `self`, they were loaded again after every node's stores
        // (a store might have changed them, as far as the compiler knows).
        let Self { mass, spline, momentum, packing, .. } = *self;
        let RegularNode { mp, mv, affine } = *node;
        // The farthest node of the stencil: one bounds check for the 3^D writes.
        let last = last_node(layout, origin);
        assert!(last < mass.len() && last < momentum.len());
        assert!(!SPLINE || last < spline.len());
        assert!(!PACK || last < packing.len());
        // SAFETY: i ≤ last, checked above; exclusive by the caller.
        s.for_each_index(layout.h, origin, layout.strides(), |i, w, d| unsafe {
            mass.update_unchecked(i, |m| *m += w * mp);
            if SPLINE {
                spline.update_unchecked(i, |m| *m += w * mp);
            }
            momentum.update_unchecked(i, |m| *m += (mv + affine * d) * w);
            if PACK {
                packing.update_unchecked(i, |v| add_packing::<D>(v, w, &d, &packing_sums));
            }
        });
    }

    /// Scatters `w (V⁰_p, V⁰_p J_p)` (`volumes`) over a particle's stencil to the volume ratio sums.
    ///
    /// # Safety
    /// No other thread writes the stencil's nodes meanwhile.
    #[inline]
    unsafe fn scatter_volume(&self, layout: &GridLayout<D>, s: &Stencil<D>, origin: usize, volumes: (Real, Real)) {
        let (v0, v0j) = volumes;
        let volume_ratio = self.volume_ratio;
        assert!(last_node(layout, origin) < volume_ratio.len());
        // SAFETY: i ≤ the stencil's last node, in bounds (checked above); exclusive by the caller.
        s.for_each_index(layout.h, origin, layout.strides(), |i, w, _| unsafe {
            volume_ratio.update_unchecked(i, |g| {
                g.0 += w * v0;
                g.1 += w * v0j;
            })
        });
    }

    /// Scatters `w [V_p, V⁰_p, V⁰_p J_p, V⁰_p (x_p − x_i)]` over a particle's stencil to the packing sums:
    /// `sums` holds the particle's occupied volume, and its rest volume and volume where it relaxes toward the
    /// packing (else zeros, and so is the centroid's sum).
    ///
    /// # Safety
    /// No other thread writes the stencil's nodes meanwhile.
    #[inline]
    unsafe fn scatter_packing(&self, layout: &GridLayout<D>, s: &Stencil<D>, origin: usize, sums: [Real; 3]) {
        let packing = self.packing;
        assert!(last_node(layout, origin) < packing.len());
        // SAFETY: i ≤ the stencil's last node, in bounds (checked above); exclusive by the caller.
        s.for_each_index(layout.h, origin, layout.strides(), |i, w, d| unsafe {
            packing.update_unchecked(i, |v| add_packing::<D>(v, w, &d, &sums))
        });
    }
}

/// Adds a particle's packing sums `[V, V⁰, V⁰ J]` (`sums`) to a node's at weight `w` and offset `d = x_i − x_p`
/// (m): `w [V, V⁰, V⁰ J, V⁰ (x_p − x_i)]`.
#[inline(always)]
fn add_packing<const D: usize>(node: &mut [Real; 6], w: Real, d: &Vector<D>, sums: &[Real; 3]) {
    node[0] += w * sums[0];
    node[1] += w * sums[1];
    node[2] += w * sums[2];
    for k in 0..D {
        node[3 + k] -= w * sums[1] * d[k];
    }
}

/// A fluid particle dilated beyond this volume ratio has separated from the bulk (spray, a free end):
/// its grid points get their mass from it alone.
pub const SEPARATED: Real = 1.1;

/// The factor (≤ 1) on the stress of a particle whose grid points get their mass from it alone, so that
/// the explicit stress update stays within its stable step. For such a particle a step maps its
/// velocity gradient C to about C − dt (V/m) (dσ/dC) Σw·Γ, with Γ the gradient block of its `M⁻¹`: the
/// materials' stable step (`stable_dt`) assumes the regular Γ = 4/h² I, and next to a wall Σw·Γ can be
/// much stiffer (its points lie on one side). Bulk particles share their nodes' mass with their
/// neighbours and need no such factor.
#[inline]
fn lone_particle_stress_scale<const D: usize>(
    minv: &crate::kernel::MlsInverse<D>,
    total: Real,
    material: &Material,
    h: Real,
    dt: Real,
) -> Real
where
    Dim<D>: DimOps<D>,
{
    let stiffness = total * -<Dim<D> as DimOps<D>>::min_sym_eigenvalue(&(-minv.gamma));
    let stable = 4.0 / (h * h) * ConstitutiveModel::<D>::stable_dt(material, h) / dt;
    if stiffness > stable {
        stable / stiffness
    } else {
        1.0
    }
}

/// With `transfer = "paper"`, a node whose MLS mass `Σ φ m_p` is below this fraction of its
/// B-spline mass `Σ w m_p` divides its momentum by that fraction of the B-spline mass instead. Near
/// walls φ = w(α + β·d) can vanish or turn negative while the force weight g = w(β + Γd) does not, so a node could get
/// a finite force on a vanishing mass; with the floor its acceleration stays within 1/fraction of
/// what the B-spline weights would give (on the regular grid φ = w and nothing changes).
pub const LOW_MASS_FRACTION: Real = 0.5;

/// Momentum → velocity of one grid point with MLS mass `m` and B-spline mass `spline`, plus `dv`
/// (gravity over the step). A point without mass gets zero velocity. Returns whether the MLS
/// mass was below [`LOW_MASS_FRACTION`] of the B-spline mass.
#[inline]
pub fn node_velocity<const D: usize>(mv: &mut Vector<D>, m: Real, spline: Real, dv: &Vector<D>) -> bool {
    if spline <= 0.0 {
        *mv = Vector::<D>::zeros();
        return false;
    }
    let floor = LOW_MASS_FRACTION * spline;
    *mv = *mv / m.max(floor) + dv;
    m < floor
}

/// Grid update on the active blocks and the boundary points: momentum → velocity, then gravity
/// `g` (m/s²) over `dt` (s). Returns the number of low-mass grid points.
pub fn grid_velocity<const D: usize>(
    t: &Transfer<'_, D>,
    grid: &mut GridState<D>,
    gravity: &Vector<D>,
    dt: Real,
) -> usize {
    let dv = gravity * dt;
    // The stable transfer's masses are positive sums (mass and "spline" mass are the same):
    // no floor acts, and none is counted.
    let track_spline = t.augmented.is_some_and(|(g, _)| g.transfer == AugmentedTransfer::Paper);
    let nodes = t.layout.num_nodes();
    let GridState { mass, spline_mass, momentum } = grid;
    let spline_of = |i: usize| if track_spline { spline_mass[i] } else { mass[i] };
    let (node_momentum, point_momentum) = momentum.split_at_mut(nodes);
    let out = Disjoint::new(node_momentum);
    let low_nodes: usize = t
        .schedule
        .active()
        .par_iter()
        .with_min_len(t.schedule.min_len(MIN_BLOCKS))
        .map(|&b| {
            let mut low = 0;
            // SAFETY: node blocks do not overlap and each active block is listed once.
            t.schedule.for_each_node(t.layout, b, |i| unsafe {
                out.update(i, |mv| low += usize::from(node_velocity(mv, mass[i], spline_of(i), &dv)));
            });
            low
        })
        .sum();
    let low_points: usize = point_momentum
        .iter_mut()
        .enumerate()
        .map(|(b, mv)| usize::from(node_velocity(mv, mass[nodes + b], spline_of(nodes + b), &dv)))
        .sum();
    low_nodes + low_points
}

/// What G2P found: particles held at walls, the first particle that went non-finite and the
/// first whose stencil left the grid, and the largest distance a particle moved along an axis (m)
/// with the particle that moved it (the lowest index among equals).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct G2pOutcome {
    pub held_at_wall: usize,
    pub non_finite: Option<usize>,
    pub left_grid: Option<usize>,
    pub max_move: Real,
    pub fastest: usize,
}

/// Per-particle results of G2P, reduced in any order to the same [`G2pOutcome`].
#[derive(Clone, Copy)]
struct G2pSum {
    held: usize,
    non_finite: usize,
    left_grid: usize,
    max_move: Real,
    fastest: usize,
}

impl G2pSum {
    const NONE: Self = Self { held: 0, non_finite: usize::MAX, left_grid: usize::MAX, max_move: 0.0, fastest: 0 };

    fn join(self, o: Self) -> Self {
        // The larger move, the lower index among equal ones: the same result in any order.
        let (max_move, fastest) =
            if o.max_move > self.max_move || (o.max_move == self.max_move && o.fastest < self.fastest) {
                (o.max_move, o.fastest)
            } else {
                (self.max_move, self.fastest)
            };
        Self {
            held: self.held + o.held,
            non_finite: self.non_finite.min(o.non_finite),
            left_grid: self.left_grid.min(o.left_grid),
            max_move,
            fastest,
        }
    }
}

/// Grid→particle transfer `v_p = Σ φ v_i`, `C_p = Σ v_i gᵀ` (eq. (4)), then, per particle near
/// a wall of an augmented grid, the fit to the wall value ([`crate::treatment::wall_fit`], `transfer =
/// "stable"`) or the hold of particles past a wall ([`hold_at_wall`], `"paper"`), advection
/// `x += dt v`, and the deformation update of its material. A material that smooths its J advances the
/// J-bar average `Σ_i w_ip J_i` of the nodes' J (`volume_ratio` after [`VolumeRatio::finish`]; empty when
/// no material smooths), gathered here: in 2D after the velocity, in a loop of its own (in the velocity's
/// loop G2P took 1.1× as long, measured); in 3D, away from walls, in the velocity's walk by rows
/// ([`regular_gather_by_rows`]). A material that relaxes its J toward the packing starts from the J-bar
/// that keeps a linear J, moved toward `1/ψ_p` ([`packing::relax`]), both gathered from `packing` (after
/// [`Packing::finish`]) at the particle's stencil of this step, and advances that.
/// The impulse each wall gave a particle of the wall table there by the wall fit (or the hold),
/// `m_p Δv_p` (N·s), goes to `pushes`, one per entry of the table in its order.
#[allow(clippy::too_many_arguments)]
pub fn g2p<const D: usize>(
    t: &Transfer<'_, D>,
    region: &dyn Region<D>,
    materials: &[Material],
    velocity: &[Vector<D>],
    volume_ratio: &VolumeRatio,
    packing: &Packing,
    particles: &mut Particles<D>,
    dt: Real,
    pushes: &mut Vec<WallPush<D>>,
) -> G2pOutcome
where
    Dim<D>: DimOps<D>,
{
    let layout = t.layout;
    pushes.clear();
    crate::math::resize_with_margin(pushes, t.augmented.map_or(0, |(_, table)| table.len()), WallPush::none());
    let pushes = Disjoint::new(pushes);
    let (h, inv_h) = (layout.h, 1.0 / layout.h);
    let apic = 4.0 * inv_h * inv_h;
    debug_assert!(keeps_f_for_all(particles, materials), "a material keeps F: it must be kept for every particle");
    let smoothing = !volume_ratio.is_empty();
    let Particles { x, v, c, f, jp, body, mass, .. } = particles;
    // Written at each particle's own index; empty when the model keeps no F.
    let f = Disjoint::new(f);
    let piece = t.schedule.min_len(task_len(x.len()));
    // One particle's transfer; the loop below calls it over pieces of `piece` particles.
    let particle =
        |p: usize, xp: &mut Vector<D>, vp: &mut Vector<D>, cp: &mut Matrix<D>, jpp: &mut Real, m: &u32, mp: Real| {
            let mut vn = Vector::<D>::zeros();
            let mut cn = Matrix::<D>::zeros();
            let mut held = false;
            // The affine state kept for the next P2G where it is not the velocity gradient `cn`.
            let mut spin = None;
            let material = &materials[*m as usize];
            let smooths = smoothing && material.smooths_volume_ratio();
            // The J-bar average of the particle's J (P2G scattered it), where it is smoothed.
            let mut jbar = 0.0;
            // The time its J relaxes over toward the packing, and the packing at its stencil, where it relaxes.
            let tau = material.packing_relaxation_time().filter(|_| !packing.is_empty());
            let mut psi = None;
            match t.augmented.and_then(|(g, table)| table.entry(p).map(|e| (g, e))) {
                None => {
                    let (s, origin) = stencil(layout, xp, inv_h);
                    if D == 3 {
                        if tau.is_some() {
                            psi = packing.at(layout, &s, origin);
                        }
                        let ratio = smooths.then_some(&volume_ratio.nodes[..]);
                        (vn, cn, jbar) = regular_gather_by_rows(layout, &s, origin, velocity, ratio);
                        cn *= apic;
                    } else {
                        assert!(last_node(layout, origin) < velocity.len());
                        if tau.is_some() {
                            // The packing's field in the velocity's walk.
                            let field = packing.field(layout, origin);
                            let mut sum = packing::Gathered::default();
                            s.for_each_index(h, origin, layout.strides(), |i, w, d| {
                                // SAFETY: i ≤ the stencil's last node, in bounds of both (checked above).
                                let vi = unsafe { velocity.get_unchecked(i) } * w;
                                vn += vi;
                                cn += vi * d.transpose();
                                unsafe { sum.add::<D>(field, i, w, &d) };
                            });
                            psi = sum.result();
                        } else {
                            s.for_each_index(h, origin, layout.strides(), |i, w, d| {
                                // SAFETY: i ≤ the stencil's last node, in bounds (checked above).
                                let vi = unsafe { velocity.get_unchecked(i) } * w;
                                vn += vi;
                                cn += vi * d.transpose();
                            });
                        }
                        cn *= apic;
                        if smooths {
                            jbar = volume_ratio_at(layout, &s, origin, volume_ratio);
                        }
                    }
                }
                Some((g, entry @ WallEntry { minv, near, tilt, slot, .. })) => {
                    if smooths || tau.is_some() {
                        let (s, origin) = stencil(layout, xp, inv_h);
                        if smooths {
                            jbar = volume_ratio_at(layout, &s, origin, volume_ratio);
                        } else {
                            psi = packing.at(layout, &s, origin);
                        }
                    }
                    let mut push = WallPush::none();
                    g.for_each_near_tilted(layout, xp, near, &tilt, |i, w, d| {
                        let vi = velocity[i];
                        let (phi, grad) = minv.shape(w, &d);
                        vn += vi * phi;
                        cn += vi * grad.transpose();
                    });
                    match g.transfer {
                        AugmentedTransfer::Paper => {
                            held = !g.surely_inside(layout, xp) && hold_at_wall(region, xp, &mut vn, &mut push);
                        }
                        AugmentedTransfer::Stable => {
                            let mut feet = region.wall_feet(xp, WALL_REACH * h);
                            // Only a particle with a face in reach can lie past one, or within the pull's
                            // margin of one (then its distance says so).
                            let margin = crate::treatment::wall_fit::PULL_MARGIN * h;
                            if !feet.is_empty()
                                && !g.surely_inside(layout, xp)
                                && region.distance(xp).distance >= -margin
                            {
                                feet.pin_past(xp, margin);
                            }
                            push = crate::treatment::wall_fit::fit_to_walls(
                                minv,
                                xp,
                                &feet,
                                &g.walls,
                                (h, dt),
                                &mut vn,
                                &mut cn,
                            );
                            spin = Some(entry.kept_affine::<Dim<D>>(&cn, h));
                        }
                    }
                    // SAFETY: each particle has its own entry in the table.
                    unsafe { pushes.update(slot, |q| *q = push.given(mp)) };
                }
            }
            *vp = vn;
            *cp = spin.unwrap_or(cn);
            let before = *xp;
            *xp += vn * dt;
            if smooths {
                *jpp = jbar;
            }
            if let (Some(tau), Some((psi, linear_jbar))) = (tau, psi) {
                // The linear J-bar extrapolates a gradient; where that leaves no volume, the particle's own J.
                let from = if linear_jbar > 0.0 { linear_jbar } else { *jpp };
                *jpp = packing::relax(from, packing::target_volume_ratio(psi, from), dt, tau);
            }
            // `a · 0` is ±0 for a finite `a` and NaN otherwise, so the sum is ±0 exactly when all are finite
            // (no branch per value). F counts where it is kept (elsewhere it is I). The particle's kinetic
            // energy must be representable too, or the run's energy is garbage.
            let zero_if_finite = |s: Real, &a: &Real| s + a * 0.0;
            let mut finite_sum = xp.iter().chain(vp.iter()).fold(0.0, zero_if_finite);
            let mut fp = Matrix::<D>::identity();
            if p < f.len() {
                // SAFETY: in bounds, and each particle is visited once.
                unsafe { f.update(p, |fq| fp = *fq) };
            }
            material.update_deformation(&mut fp, jpp, &cn, dt);
            if p < f.len() {
                // SAFETY: as above.
                unsafe { f.update(p, |fq| *fq = fp) };
                finite_sum = fp.iter().fold(finite_sum, zero_if_finite);
            }
            let finite = finite_sum == 0.0 && crate::particles::energy_in_range(mp, vp);
            G2pSum {
                held: usize::from(held),
                non_finite: if finite { usize::MAX } else { p },
                left_grid: if stencil_in_grid(layout, xp, inv_h) { usize::MAX } else { p },
                // The distance actually moved (rounding can move x by more than |v dt| in f32).
                max_move: (*xp - before).amax(),
                fastest: p,
            }
        };
    // A piece's particles in a plain loop, which the compiler sees whole: with each particle an item of
    // the parallel iterator, the f32 build called the body once a particle and G2P took 1.3× as long
    // (f64 1.05×; measured on the 256² dam break).
    let sum = x
        .par_chunks_mut(piece)
        .zip(v.par_chunks_mut(piece))
        .zip(c.par_chunks_mut(piece))
        .zip(jp.par_chunks_mut(piece))
        .zip(body.par_chunks(piece))
        .zip(mass.par_chunks(piece))
        .enumerate()
        .map(|(k, (((((xs, vs), cs), js), bs), ms))| {
            let mut sum = G2pSum::NONE;
            for (j, (((((xp, vp), cp), jpp), m), &mp)) in
                xs.iter_mut().zip(vs).zip(cs).zip(js).zip(bs).zip(ms).enumerate()
            {
                sum = sum.join(particle(k * piece + j, xp, vp, cp, jpp, m, mp));
            }
            sum
        })
        .reduce(|| G2pSum::NONE, G2pSum::join);
    let first = |p: usize| (p != usize::MAX).then_some(p);
    G2pOutcome {
        held_at_wall: sum.held,
        non_finite: first(sum.non_finite),
        left_grid: first(sum.left_grid),
        max_move: sum.max_move,
        fastest: sum.fastest,
    }
}

/// What G2P gathers for a particle away from walls, row by row (3D): its velocity `Σ_i w v_i`, the sum
/// `B = Σ_i w v_i d_iᵀ` (`d_i = x_i − x_p`; the caller scales it to `C`), and, with the nodes' volume ratios
/// `ratio`, its J-bar average `Σ_i w J_i` (0 without).
///
/// `B` is formed from first moments: with `d_k = (o_k − fx_k) h` (`o` the node's offset in cells, `fx` the
/// particle's position in the stencil), column k is `h (m_k − fx_k v)`, `m_k = Σ_i o_k w v_i`. A node adds
/// `w v_i` to its row's sum; a row adds its sum to the velocity, and its nodes' first-axis moment and its
/// sum times its other offsets to the moments: about 14 operations a node (the weight and `w v_i` included)
/// where the per-node sums took 26. Equal to the per-node sums to rounding, not bitwise: `m_k` and `fx_k v`
/// are of the size of the velocities, so B's rounding error is of the per-node sums' order, ε |v| h.
///
/// 3D dam break at 64³, f64, one thread, against the per-node loop and a separate J-bar loop: G2P 0.748× its
/// time (see README, Performance). In 2D, where the outer product is 8 of a node's 13 operations, the row form
/// was no faster (G2P 1.007×), and the per-node loop stays. In f32 on x86-64 the row sums are taken in SSE2
/// registers ([`crate::step::rows_sse`]), bitwise the same.
#[inline(always)]
fn regular_gather_by_rows<const D: usize>(
    layout: &GridLayout<D>,
    s: &Stencil<D>,
    origin: usize,
    velocity: &[Vector<D>],
    ratio: Option<&[(Real, Real)]>,
) -> (Vector<D>, Matrix<D>, Real) {
    let last = last_node(layout, origin);
    assert!(last < velocity.len() && ratio.is_none_or(|r| last < r.len()));
    let (vn, moments, jbar) = row_sums(layout, s, origin, velocity, ratio);
    let mut b = Matrix::<D>::zeros();
    for (k, m) in moments.iter().enumerate() {
        b.set_column(k, &((m - vn * s.fx[k]) * layout.h));
    }
    (vn, b, jbar)
}

/// The sums [`regular_gather_by_rows`] forms B from: `Σ w v_i`, the first moments `Σ o_k w v_i` and `Σ w J_i`
/// (0 without `ratio`), the stencil's last node in bounds of both arrays (checked by the caller).
#[inline(always)]
fn row_sums<const D: usize>(
    layout: &GridLayout<D>,
    s: &Stencil<D>,
    origin: usize,
    velocity: &[Vector<D>],
    ratio: Option<&[(Real, Real)]>,
) -> (Vector<D>, [Vector<D>; D], Real) {
    #[cfg(all(target_arch = "x86_64", feature = "f32"))]
    if D == 3 {
        // The same sums in SSE2 registers, bitwise equal (`rows_sse`): G2P 0.856× its time (f64 keeps the
        // loop below).
        let strides: [usize; 3] = std::array::from_fn(|k| layout.strides()[k]);
        let w: [[Real; 3]; 3] = std::array::from_fn(|k| s.w[k]);
        const { assert!(std::mem::size_of::<Vector<D>>() == D * std::mem::size_of::<Real>()) };
        let velocity = velocity.as_ptr() as *const Real;
        // SAFETY: a `Vector<D>` is its D reals in order, without padding (nalgebra's `Matrix` is `repr(C)`
        // over `ArrayStorage`, `repr(transparent)` over `[[Real; D]; 1]`; the size checked above), so the
        // nodes' velocities are `3 len` reals; the stencil's last node is in bounds of both arrays (checked by
        // the caller).
        let sums = unsafe { crate::step::rows_sse::gather_rows_f32(velocity, ratio, origin, &strides, &w) };
        let vector = |x: &[Real; 3]| Vector::<D>::from_fn(|k, _| x[k]);
        return (vector(&sums.velocity), std::array::from_fn(|k| vector(&sums.moments[k])), sums.jbar);
    }
    let (mut vn, mut moments, mut jbar) = (Vector::<D>::zeros(), [Vector::<D>::zeros(); D], 0.0);
    let stride = layout.strides()[0];
    s.for_each_row(layout.strides(), |o, row, w_rest| {
        let u: [Vector<D>; 3] = std::array::from_fn(|a| {
            let (i, w) = (origin + row + a * stride, s.w[0][a] * w_rest);
            if let Some(r) = ratio {
                // SAFETY: i ≤ the stencil's last node (`Stencil::for_each_row`'s bound), in bounds
                // (checked by the caller).
                jbar += w * unsafe { r.get_unchecked(i) }.1;
            }
            // SAFETY: as above.
            unsafe { velocity.get_unchecked(i) * w }
        });
        let across = u[0] + u[1] + u[2];
        moments[0] += u[1] + u[2] + u[2];
        for k in 1..D {
            moments[k] += across * o[k] as Real;
        }
        vn += across;
    });
    (vn, moments, jbar)
}

/// Whether the particles hold F for each of them where a material keeps one (otherwise they read F = I).
fn keeps_f_for_all<const D: usize>(particles: &Particles<D>, materials: &[Material]) -> bool
where
    Dim<D>: DimOps<D>,
{
    particles.f.len() == particles.len() || !materials.iter().any(ConstitutiveModel::<D>::keeps_deformation_gradient)
}

/// Distance (cell widths) within which a wall face enters a particle's fit: the B-spline support.
pub const WALL_REACH: Real = 1.5;

/// A particle that has crossed a wall (its MLS fit then extrapolates, and left alone it can run
/// away) loses the part of its velocity that would carry it deeper, `v −= n·max(v·n, 0)`, whatever
/// the wall's condition; moving back out is free. Returns whether it was held.
#[inline]
pub fn hold_at_wall<const D: usize>(
    region: &dyn Region<D>,
    x: &Vector<D>,
    v: &mut Vector<D>,
    push: &mut WallPush<D>,
) -> bool {
    let d = region.distance(x);
    let into = v.dot(&d.normal);
    if d.distance > 0.0 && into > 0.0 {
        *v -= d.normal * into;
        push.add(d.wall, -d.normal * into, x);
        true
    } else {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Point, Polygon, WallShape, Walls2};
    use crate::material::WeaklyCompressibleFluid;
    use crate::step::schedule::Binning;
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
            ps.push(x, v, m, 1.0, 0);
            let last = ps.len() - 1;
            ps.c[last] = Matrix2::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5, rnd() - 0.5);
        }
        ps
    }

    fn angular_momentum(ps: &Particles<2>, h: f64) -> f64 {
        // Particle angular momentum including the APIC affine part: Σ m (x × v) + m h²/4 (C₁₀ − C₀₁).
        (0..ps.len())
            .map(|p| ps.mass[p] * (ps.x[p].perp(&ps.v[p]) + h * h / 4.0 * (ps.c[p][(1, 0)] - ps.c[p][(0, 1)])))
            .sum()
    }

    /// A stress-free material: P2G → G2P must then conserve momentum exactly.
    /// P2G of dust (no stress, no density sums) at dt = 1 ms.
    fn p2g_dust(t: &Transfer<'_, 2>, ps: &Particles<2>, grid: &mut GridState<2>) {
        let mut density = vec![0.0; ps.len()];
        p2g(t, &dust(), ps, None, &mut density, 1e-3, grid, &mut VolumeRatio::default(), &mut Packing::default());
    }

    /// G2P of dust from the node velocities `velocity`, with dt = 0 (positions stay).
    fn g2p_dust(t: &Transfer<'_, 2>, walls: &Walls2, velocity: &[Vector2<f64>], ps: &mut Particles<2>) -> G2pOutcome {
        g2p(t, walls, &dust(), velocity, &VolumeRatio::default(), &Packing::default(), ps, 0.0, &mut Vec::new())
    }

    fn dust() -> Vec<Material> {
        vec![Material::Fluid(WeaklyCompressibleFluid::dust(1.0))]
    }

    /// The gather by rows is the per-node gather regrouped: the velocity, `Σ w v dᵀ` and the J-bar average of
    /// particles anywhere in a cell agree with the per-node sums to rounding (relative 1e-13 of the sums'
    /// scale, ~500 ulp, in 2D and 3D), and without volume ratios the average is 0.
    #[test]
    fn the_gather_by_rows_regroups_the_per_node_sums() {
        fn check<const D: usize>() {
            let layout = GridLayout::<D>::new(0.1, [6; D]);
            let mut s = 99u64;
            let mut rnd = || {
                s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                (s >> 11) as f64 / (1u64 << 53) as f64
            };
            let n = layout.num_nodes();
            let velocity: Vec<Vector<D>> = (0..n).map(|_| Vector::<D>::from_fn(|_, _| rnd() - 0.5)).collect();
            let ratio: Vec<(Real, Real)> = (0..n).map(|_| (1.0, 0.8 + 0.4 * rnd())).collect();
            for _ in 0..200 {
                let x = Vector::<D>::from_fn(|_, _| 0.15 + 0.3 * rnd());
                let (st, origin) = stencil(&layout, &x, 1.0 / layout.h);
                let (mut v, mut b, mut j) = (Vector::<D>::zeros(), Matrix::<D>::zeros(), 0.0);
                st.for_each_index(layout.h, origin, layout.strides(), |i, w, d| {
                    v += velocity[i] * w;
                    b += velocity[i] * w * d.transpose();
                    j += w * ratio[i].1;
                });
                let (vr, br, jr) = regular_gather_by_rows(&layout, &st, origin, &velocity, Some(&ratio));
                assert!((vr - v).amax() < 1e-13, "velocity {vr} against {v}");
                // B's scale is |v| h: 0.5 × 0.1 m.
                assert!((br - b).amax() < 1e-13 * 0.05, "B {br} against {b}");
                assert!((jr - j).abs() < 1e-13, "J-bar {jr} against {j}");
                assert_eq!(regular_gather_by_rows(&layout, &st, origin, &velocity, None).2, 0.0);
            }
        }
        check::<2>();
        check::<3>();
    }

    thread_local! {
        /// P2G scatters through tiles in 3D f64 too, on this thread ([`through_tiles`]).
        pub static TILES: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
    }

    /// 4,000 particles spread over [0.1, 0.9]³ m (inside a 20³ grid of 0.05 m cells, 1 m wide), with random
    /// velocities, masses (0.5–1.5 kg), rest volumes 1e-3 m³, C and J in [0.9, 1.1], drawn from `seed`.
    fn particles_in_a_box_3d(seed: u64) -> Particles<3> {
        let mut s = seed;
        let mut rnd = || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut ps = Particles::<3>::default();
        for _ in 0..4000 {
            let x = Vector::<3>::from_fn(|_, _| 0.1 + 0.8 * rnd());
            ps.push(x, Vector::<3>::from_fn(|_, _| rnd() - 0.5), 0.5 + rnd(), 1e-3, 0);
            let last = ps.len() - 1;
            ps.c[last] = Matrix::<3>::from_fn(|_, _| rnd() - 0.5);
            ps.jp[last] = 0.9 + 0.2 * rnd();
        }
        ps
    }

    /// P2G through the 3D tiles gives the grid of the direct scatter, regrouped: a water body of random J
    /// (stress from its pressure and viscosity) with its J-bar sums, whose mass, momentum and J-bar sums agree
    /// node by node to rounding (1e-12 of each field's largest value: ~20 particles a node); on one thread,
    /// where the tiles are those P2G runs in f32.
    #[test]
    fn p2g_through_tiles_gives_the_grid_of_the_direct_scatter() {
        let layout = GridLayout::<3>::new(0.05, [20; 3]);
        let ps = particles_in_a_box_3d(11);
        let water = WeaklyCompressibleFluid {
            stiffness: 1e5,
            gamma: 7.0,
            viscosity: 1e-3,
            density_estimate: crate::material::DensityEstimate::Deformation,
            relaxation_time: None,
            ..WeaklyCompressibleFluid::dust(1000.0)
        };
        let materials = vec![Material::Fluid(water)];
        let mut schedule = Schedule::new(&layout);
        schedule.sort(&layout, &ps.x, &mut Binning::default()).unwrap();
        let t = Transfer { layout: &layout, schedule: &schedule, augmented: None };
        let run = |materials: &[Material], tiles: bool| {
            TILES.with(|t| t.set(tiles));
            let mut grid = GridState::new(layout.num_nodes(), false);
            let mut ratio = VolumeRatio::new(layout.num_nodes());
            let mut density = vec![0.0; ps.len()];
            p2g(&t, materials, &ps, None, &mut density, 1e-4, &mut grid, &mut ratio, &mut Packing::default());
            TILES.with(|t| t.set(false));
            (grid, ratio, density)
        };
        let (direct, direct_ratio, direct_density) = run(&materials, false);
        let (tiled, tiled_ratio, tiled_density) = run(&materials, true);
        assert_eq!(tiled_density, direct_density);
        let m_scale = direct.mass.iter().fold(0.0f64, |a, &m| a.max(m));
        let p_scale = direct.momentum.iter().fold(0.0f64, |a, p| a.max(p.amax()));
        // The stress is in the sums compared: without it the momentum moves by a good part of its scale.
        let (stress_free, _, _) = run(&dust(), false);
        let by_stress =
            (0..layout.num_nodes()).fold(0.0f64, |a, i| a.max((direct.momentum[i] - stress_free.momentum[i]).amax()));
        assert!(by_stress > 0.1 * p_scale, "the stress moves the momentum by {by_stress} of {p_scale}");
        for i in 0..layout.num_nodes() {
            assert!((tiled.mass[i] - direct.mass[i]).abs() <= 1e-12 * m_scale, "node {i}: mass");
            assert!((tiled.momentum[i] - direct.momentum[i]).amax() <= 1e-12 * p_scale, "node {i}: momentum");
            assert_eq!(tiled_ratio.nodes[i], direct_ratio.nodes[i], "node {i}: the J-bar sums, scattered directly");
        }
    }

    /// The 3D tile's scatter gives each node the sums of the per-node scatter, regrouped: mass and momentum
    /// agree to rounding (1e-12 of the sums' scale: ~20 particles a node, terms of O(1)) on a grid of several
    /// blocks along each axis, whose tiles overlap their neighbours', and every node outside the stencils is
    /// left zero.
    #[test]
    fn the_3d_tile_gives_the_nodes_the_per_node_sums() {
        let layout = GridLayout::<3>::new(0.05, [20; 3]);
        let ps = particles_in_a_box_3d(5);
        let mut schedule = Schedule::new(&layout);
        schedule.sort(&layout, &ps.x, &mut Binning::default()).unwrap();
        // The tile's scatter as P2G runs it in f32 (this crate's tests run in f64), block by block.
        let mut grid = GridState::new(layout.num_nodes(), false);
        let (grid_mass, grid_momentum) = (Disjoint::new(&mut grid.mass), Disjoint::new(&mut grid.momentum));
        schedule.for_each_block(|reach, block| {
            with_tile(|tile| {
                tile.begin();
                for &p in block {
                    let p = p as usize;
                    let (st, _) = stencil(&layout, &ps.x[p], 1.0 / layout.h);
                    reach.check(&st.base);
                    let (mp, affine) = (ps.mass[p], ps.c[p] * ps.mass[p]);
                    tile.scatter(reach, &st, layout.h, mp, &(ps.v[p] * mp), &affine);
                }
                // SAFETY: blocks of one colour share no node; one thread here.
                unsafe { tile.add_to_grid(&layout, reach, grid_mass, grid_momentum) };
            })
        });

        let (mut mass, mut momentum) = (vec![0.0; layout.num_nodes()], vec![Vector::<3>::zeros(); layout.num_nodes()]);
        for p in 0..ps.len() {
            let (st, origin) = stencil(&layout, &ps.x[p], 1.0 / layout.h);
            let (mp, affine) = (ps.mass[p], ps.c[p] * ps.mass[p]);
            st.for_each_index(layout.h, origin, layout.strides(), |i, w, d| {
                mass[i] += w * mp;
                momentum[i] += (ps.v[p] * mp + affine * d) * w;
            });
        }
        for i in 0..layout.num_nodes() {
            assert!(
                (grid.mass[i] - mass[i]).abs() < 1e-12 * 20.0,
                "node {i}: mass {} against {}",
                grid.mass[i],
                mass[i]
            );
            assert!((grid.momentum[i] - momentum[i]).amax() < 1e-12 * 20.0, "node {i}: momentum");
            if mass[i] == 0.0 {
                assert_eq!((grid.mass[i], grid.momentum[i]), (0.0, Vector::<3>::zeros()), "node {i}: untouched");
            }
        }
        assert!(mass.iter().filter(|&&m| m > 0.0).count() > 5000, "the particles reach most nodes");
    }

    /// With no walls and no stress, P2G → G2P conserves mass, linear and angular momentum to
    /// round-off (relative 1e-12: a few hundred additions of O(1) terms in double precision).
    #[test]
    fn transfers_conserve_mass_and_momentum() {
        let h = 0.05;
        let layout = GridLayout::<2>::new(h, [20, 20]);
        let mut ps = random_particles(300);
        let mut schedule = Schedule::new(&layout);
        schedule.sort(&layout, &ps.x, &mut Binning::default()).unwrap();
        let t = Transfer { layout: &layout, schedule: &schedule, augmented: None };
        let mut grid = GridState::new(layout.num_nodes(), false);
        p2g_dust(&t, &ps, &mut grid);

        let mass: f64 = ps.mass.iter().sum();
        let p_particles = ps.momentum();
        let l_particles = angular_momentum(&ps, h);
        let grid_mass: f64 = grid.mass.iter().sum();
        let p_grid = grid.momentum.iter().fold(Vector2::zeros(), |a, b| a + b);
        let l_grid: f64 = (0..layout.num_nodes()).map(|i| layout.position(i).perp(&grid.momentum[i])).sum();
        assert!((grid_mass - mass).abs() < 1e-12 * mass);
        assert!((p_grid - p_particles).norm() < 1e-12 * mass);
        assert!((l_grid - l_particles).abs() < 1e-12 * mass, "{l_grid} vs {l_particles}");

        grid_velocity(&t, &mut grid, &Vector2::zeros(), 1e-3);
        let before = ps.clone();
        let walls = Walls2::new(vec![], Point::new(1.0, 1.0));
        let outcome = g2p_dust(&t, &walls, &grid.momentum, &mut ps);
        assert_eq!((outcome.held_at_wall, outcome.non_finite, outcome.left_grid), (0, None, None));
        assert_eq!(ps.x, before.x, "dt = 0 leaves positions");
        let p_back = ps.momentum();
        let l_back = angular_momentum(&ps, h);
        assert!((p_back - p_particles).norm() < 1e-12 * mass, "{p_back} vs {p_particles}");
        assert!((l_back - l_particles).abs() < 1e-12 * mass, "{l_back} vs {l_particles}");
    }

    /// The J-bar average (P2G scatters V⁰ and V⁰J, the grid stage takes their ratio, G2P gathers it) keeps
    /// the total volume Σ V⁰ J (to relative 1e-12: sums of a few thousand O(1) terms), returns a uniform J
    /// unchanged (to 1e-14), and removes sub-cell noise: a J random in ±10% per particle comes back with
    /// less than half its spread (300 particles, ~2 a cell, each averaged over ~9 cells).
    #[test]
    fn volume_ratio_average_keeps_the_volume_and_smooths() {
        let h = 0.05;
        let layout = GridLayout::<2>::new(h, [20, 20]);
        let mut s = 7u64;
        let mut rnd = || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut ps = random_particles(300);
        let mut schedule = Schedule::new(&layout);
        schedule.sort(&layout, &ps.x, &mut Binning::default()).unwrap();
        let t = Transfer { layout: &layout, schedule: &schedule, augmented: None };
        let walls = Walls2::new(vec![], Point::new(1.0, 1.0));
        let spread = |j: &[f64]| {
            let mean = j.iter().sum::<f64>() / j.len() as f64;
            (j.iter().map(|a| (a - mean).powi(2)).sum::<f64>() / j.len() as f64).sqrt()
        };
        // Stress-free, with its J smoothed.
        let fluid = vec![Material::Fluid(WeaklyCompressibleFluid {
            density_estimate: crate::material::DensityEstimate::Deformation,
            relaxation_time: None,
            ..WeaklyCompressibleFluid::dust(1.0)
        })];
        for uniform in [true, false] {
            for p in 0..ps.len() {
                ps.vol0[p] = 0.5 + rnd();
                ps.jp[p] = if uniform { 1.1 } else { 0.9 + 0.2 * rnd() };
            }
            let (before, volume) = (ps.jp.clone(), ps.vol0.iter().zip(&ps.jp).map(|(v, j)| v * j).sum::<f64>());
            let mut grid = GridState::new(layout.num_nodes(), false);
            let mut ratio = VolumeRatio::new(layout.num_nodes());
            p2g(&t, &fluid, &ps, None, &mut vec![0.0; ps.len()], 1e-3, &mut grid, &mut ratio, &mut Packing::default());
            grid_velocity(&t, &mut grid, &Vector2::zeros(), 1e-3);
            ratio.finish(&layout, &schedule);
            g2p(&t, &walls, &fluid, &grid.momentum, &ratio, &Packing::default(), &mut ps, 0.0, &mut Vec::new());
            let after: f64 = ps.vol0.iter().zip(&ps.jp).map(|(v, j)| v * j).sum();
            assert!((after - volume).abs() < 1e-12 * volume, "total volume {after} vs {volume}");
            if uniform {
                assert!(ps.jp.iter().all(|&j| (j - 1.1).abs() < 1e-14), "a uniform J changed");
            } else {
                let (a, b) = (spread(&ps.jp), spread(&before));
                assert!(a < 0.5 * b, "spread {a} after, {b} before");
            }
        }
    }

    /// A node whose MLS mass falls below half its B-spline mass divides by that half: a vanishing
    /// mass cannot turn a finite force into a runaway velocity, and the node is counted.
    #[test]
    fn low_mass_nodes_are_bounded_and_counted() {
        let dv = Vector2::zeros();
        let mut mv = Vector2::new(2.0, 0.0);
        assert!(!node_velocity(&mut mv, 1.0, 1.0, &dv));
        assert_eq!(mv, Vector2::new(2.0, 0.0));
        let mut mv = Vector2::new(0.3, 0.0);
        assert!(node_velocity(&mut mv, 0.1, 1.0, &dv));
        assert!((mv - Vector2::new(0.6, 0.0)).norm() < 1e-15);
        let mut mv = Vector2::new(-0.4, 0.0);
        assert!(node_velocity(&mut mv, -0.2, 1.0, &dv));
        assert!((mv - Vector2::new(-0.8, 0.0)).norm() < 1e-15);
        let mut mv = Vector2::new(5.0, 0.0);
        assert!(!node_velocity(&mut mv, 0.0, 0.0, &dv));
        assert_eq!(mv, Vector2::zeros());
    }

    /// Next to a wall the truncated kernel reads a uniform fluid of density 1 about 25% light; with the
    /// wall fractions it reads 1 within 4% (the particles' h/4 lattice and the h/8 sampling of the
    /// fractions are two quadratures of the same cut kernel, a few percent apart at the cut).
    #[test]
    fn wall_fractions_restore_density_next_to_a_wall() {
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
        let mut schedule = Schedule::new(&layout);
        schedule.sort(&layout, &x, &mut Binning::default()).unwrap();
        let mut grid_mass = vec![0.0; layout.num_nodes()];
        scatter_mass(&layout, &schedule, &x, &mass, &mut grid_mass);
        let probe = Stencil::new(&Point::new(0.5, floor + 0.2 * h), 1.0 / h);
        let origin = layout.stencil_origin(&probe.base).unwrap();
        let plain = density_at(&layout, &probe, origin, &grid_mass, None);
        let corrected = density_at(&layout, &probe, origin, &grid_mass, Some(&fractions));
        assert!(plain < 0.8, "truncated kernel: {plain}");
        assert!((corrected - 1.0).abs() < 0.04, "corrected: {corrected}");
    }

    /// A particle past a wall keeps its motion along the wall and back out, but not deeper in;
    /// particles inside are untouched.
    #[test]
    fn particles_past_a_wall_are_held() {
        let walls = Walls2::new(vec![], Point::new(1.0, 1.0)); // the domain box alone
        let mut v = Point::new(1.0, -2.0);
        assert!(hold_at_wall(&walls, &Point::new(0.5, -0.01), &mut v, &mut WallPush::none()));
        assert_eq!(v, Point::new(1.0, 0.0));
        let mut v = Point::new(1.0, 2.0);
        assert!(!hold_at_wall(&walls, &Point::new(0.5, -0.01), &mut v, &mut WallPush::none()));
        assert_eq!(v, Point::new(1.0, 2.0));
        let mut v = Point::new(1.0, -2.0);
        assert!(!hold_at_wall(&walls, &Point::new(0.5, 0.2), &mut v, &mut WallPush::none()));
        assert_eq!(v, Point::new(1.0, -2.0));
    }

    /// A lone particle's stress keeps its full size while its MLS system is no stiffer than the regular
    /// grid's at the materials' stable step, and is scaled by exactly the excess beyond it.
    #[test]
    fn lone_particle_stress_is_scaled_to_the_stable_step() {
        let h = 0.1;
        let water = Material::Fluid(WeaklyCompressibleFluid {
            density: 1000.0,
            stiffness: 1e5,
            gamma: 7.0,
            viscosity: 1.0,
            min_pressure: 0.0,
            density_estimate: crate::material::DensityEstimate::Deformation,
            relaxation_time: None,
        });
        let stable = ConstitutiveModel::<2>::stable_dt(&water, h);
        let regular = crate::kernel::MlsInverse::<2>::regular(h);
        assert!((lone_particle_stress_scale(&regular, 1.0, &water, h, stable) - 1.0).abs() < 1e-12);
        assert_eq!(lone_particle_stress_scale(&regular, 1.0, &water, h, 0.5 * stable), 1.0);
        let stiff = crate::kernel::MlsInverse::<2> { gamma: regular.gamma * 6.0, ..regular };
        let scale = lone_particle_stress_scale(&stiff, 1.0, &water, h, 0.5 * stable);
        assert!((scale - 2.0 / 6.0).abs() < 1e-12, "{scale}");
    }

    /// P2G sums are bitwise identical on 1 and 2 threads (the coloured scatter fixes their order).
    #[test]
    fn scatter_is_reproducible_across_thread_counts() {
        let h = 0.02;
        let layout = GridLayout::<2>::new(h, [50, 50]);
        let ps = random_particles(20_000);
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| {
                let mut schedule = Schedule::new(&layout);
                schedule.sort(&layout, &ps.x, &mut Binning::default()).unwrap();
                // One thread takes the serial forms, two the parallel ones: the sums must not tell.
                assert_eq!(schedule.parallel(), threads > 1);
                let t = Transfer { layout: &layout, schedule: &schedule, augmented: None };
                let mut grid = GridState::new(layout.num_nodes(), false);
                p2g_dust(&t, &ps, &mut grid);
                grid
            })
        };
        let (one, two) = (run(1), run(2));
        assert_eq!(one.mass, two.mass);
        assert_eq!(one.momentum, two.momentum);
    }

    /// A particle moved past its block's reach without re-binning is refused (a panic), never
    /// scattered where another thread of the same colour may write.
    #[test]
    #[should_panic(expected = "moved out of its block")]
    fn particles_moved_without_rebinning_are_refused() {
        let layout = GridLayout::<2>::new(0.02, [50, 50]);
        let mut ps = random_particles(100);
        let mut schedule = Schedule::new(&layout);
        schedule.sort(&layout, &ps.x, &mut Binning::default()).unwrap();
        ps.x[7].x += 12.0 * layout.h; // more than a block (8) plus the slack (2)
        let t = Transfer { layout: &layout, schedule: &schedule, augmented: None };
        let mut grid = GridState::new(layout.num_nodes(), false);
        p2g_dust(&t, &ps, &mut grid);
    }
}
