//! Wall boundary conditions. Boundary handling is a family chosen by name:
//! the naive grid-node projection (here) and, next, the augmented grid of
//! Toyota & Umetani 2024.

use crate::geometry::Region;
use crate::grid::GridLayout;
use crate::math::{Real, Vector};
use serde::{Deserialize, Serialize};

/// What a wall does to the velocity of the material against it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WallCondition {
    /// No-slip: the velocity equals the wall's.
    #[default]
    Sticky,
    /// Full-slip: the normal component (relative to the wall) is removed.
    Slip,
    /// Only a normal component into the wall is removed; the material may leave it.
    Separate,
}

impl WallCondition {
    /// Applies the condition to velocity `v` at a wall of outward normal `n`
    /// (unit, into the wall) moving at `wall_v` (its geometry stays still).
    #[inline]
    pub fn apply<const D: usize>(self, v: Vector<D>, n: &Vector<D>, wall_v: &Vector<D>) -> Vector<D> {
        let rel = v - wall_v;
        let vn = rel.dot(n);
        match self {
            WallCondition::Sticky => *wall_v,
            WallCondition::Slip => v - n * vn,
            WallCondition::Separate if vn > 0.0 => v - n * vn,
            WallCondition::Separate => v,
        }
    }
}

/// Condition and (tangential) velocity of one wall.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WallMotion<const D: usize> {
    pub condition: WallCondition,
    /// Velocity of the wall surface (m/s).
    pub velocity: Vector<D>,
}

/// A grid node on the wall side of the region, with the condition it gets.
#[derive(Clone, Copy, Debug)]
pub struct WallNode<const D: usize> {
    pub node: usize,
    pub normal: Vector<D>,
    pub wall: usize,
}

/// The classic MLS-MPM boundary: every grid node outside the material region
/// (or exactly on its wall) gets its wall's condition after the grid update.
#[derive(Clone, Debug)]
pub struct NaiveBoundary<const D: usize> {
    pub nodes: Vec<WallNode<D>>,
    pub walls: Vec<WallMotion<D>>,
}

impl<const D: usize> NaiveBoundary<D> {
    /// Classifies every node of `layout` against `region` once; walls do not move.
    pub fn new(layout: &GridLayout<D>, region: &dyn Region<D>, walls: Vec<WallMotion<D>>) -> Self {
        let nodes = (0..layout.num_nodes())
            .filter_map(|node| {
                let d = region.distance(&layout.position(node));
                (d.distance >= 0.0).then_some(WallNode { node, normal: d.normal, wall: d.wall })
            })
            .collect();
        Self { nodes, walls }
    }

    /// Projects the grid velocities of wall nodes (after momentum → velocity).
    pub fn apply(&self, mass: &[Real], velocity: &mut [Vector<D>]) {
        for w in &self.nodes {
            if mass[w.node] > 0.0 {
                let m = &self.walls[w.wall];
                velocity[w.node] = m.condition.apply(velocity[w.node], &w.normal, &m.velocity);
            }
        }
    }
}

/// How walls act on the grid, chosen by name (`method` in the API and CLI).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Grid-node projection on the regular grid (the baseline of the paper).
    #[default]
    Naive,
    /// Augmented grid points on the walls (Toyota & Umetani 2024).
    Augmented,
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector2;

    #[test]
    fn conditions_project_velocity() {
        let n = Vector2::new(0.0, -1.0);
        let still = Vector2::zeros();
        let into = Vector2::new(2.0, -3.0);
        let away = Vector2::new(2.0, 3.0);
        assert_eq!(WallCondition::Sticky.apply(into, &n, &still), still);
        assert_eq!(WallCondition::Slip.apply(into, &n, &still), Vector2::new(2.0, 0.0));
        assert_eq!(WallCondition::Slip.apply(away, &n, &still), Vector2::new(2.0, 0.0));
        assert_eq!(WallCondition::Separate.apply(into, &n, &still), Vector2::new(2.0, 0.0));
        assert_eq!(WallCondition::Separate.apply(away, &n, &still), away);
        let belt = Vector2::new(1.5, 0.0);
        assert_eq!(WallCondition::Sticky.apply(into, &n, &belt), belt);
        assert_eq!(WallCondition::Slip.apply(into, &n, &belt), Vector2::new(2.0, 0.0));
    }
}
