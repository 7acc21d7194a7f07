//! Extra attributes (format 1.2's ATTRIBUTES and NODE_ATTRIBUTES sections): further
//! per-particle columns beside the first attribute, so that one file colours by any of
//! them (a potential energy, a kinetic energy, an SPH run's density and temperature)
//! without converting the frame again.
//!
//! How it works: the hierarchy is built as ever (with the first attribute, which its
//! representatives average as they are made); each extra column is then laid out in the
//! built file's particle order and quantized over its own range as the first is, and
//! each node's mean is the area-weighted mean of the particles below it (the same
//! definition as the first attribute's: area `r²`, the particle's own radius as stored
//! or its species', a plain mean where the areas sum to 0), summed in `f64` over the
//! node's own particles, one contiguous run of the finest level (every level's nodes
//! together sum each particle once: the levels' count of passes in all). A column kept
//! as its logarithm (an SPH column density spanning decades) stores each value's
//! `log10` over the logarithms' range, and each node's mean as the logarithm of its
//! linear mean: the sums stay linear, so `10^mean` times a cluster's area is its
//! particles' light, as for the first attribute with `attribute_log10`.

use std::ops::Range;

use mdlod_format::layout::{LevelRecord, NodeRecord};
use mdlod_format::meta::{AttributeInfo, Species};
use rayon::prelude::*;

use super::{BuildError, Hierarchy};

/// One extra attribute of a built hierarchy.
#[derive(Clone, Debug, PartialEq)]
pub struct ExtraAttribute {
    pub info: AttributeInfo,
    /// Quantized value per particle, in the file's particle order.
    pub values: Vec<u16>,
    /// Area-weighted mean per node.
    pub node_means: Vec<f32>,
}

/// For every node (indexed as the node table), the range of its particles: the run of
/// the finest level below it, found bottom up through the children's ranges.
pub fn particle_ranges(levels: &[LevelRecord], nodes: &[NodeRecord]) -> Vec<Range<u64>> {
    let last = levels.len().saturating_sub(1);
    let mut ranges = vec![0..0; nodes.len()];
    for l in (0..last).rev() {
        let first = levels[l].node_first as usize;
        let count = levels[l].point_count as usize;
        for i in first..(first + count).min(nodes.len()) {
            let n = &nodes[i];
            let children =
                u64::from(n.child_first)..u64::from(n.child_first) + u64::from(n.child_count);
            ranges[i] = if l + 1 == last || children.is_empty() {
                children
            } else {
                let below = levels[l + 1].node_first;
                let at = |c: u64| ranges.get((below + c) as usize).cloned().unwrap_or(0..0);
                at(children.start).start..at(children.end - 1).end
            };
        }
    }
    ranges
}

/// One column for [`extra_attributes`]: its name as the file gives it, one value per
/// particle in the input's order, and whether the file keeps its base-10 logarithm
/// (`AttributeInfo::log10`; the values must then be above 0).
pub struct ExtraColumn<'a> {
    pub name: &'a str,
    pub values: &'a [f32],
    pub log10: bool,
}

/// Lays out each of `columns` in `h`'s particle order, quantizes it over its range (of
/// the logarithms, for a column kept as its logarithm), and averages it over every node.
/// `species` are the species the hierarchy was built with (their radii weigh the
/// particles without radii of their own). The nodes' particle runs and the particles'
/// areas are found once for all the columns.
pub fn extra_attributes(
    h: &Hierarchy,
    columns: &[ExtraColumn],
    species: &[Species],
) -> Result<Vec<ExtraAttribute>, BuildError> {
    let mut infos = Vec::with_capacity(columns.len());
    for c in columns {
        check_finite(c.values)?;
        if c.log10 {
            check_positive(c.name, c.values)?;
        }
        let (min, max) = c
            .values
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
                (lo.min(v), hi.max(v))
            });
        // (`log10` is monotonic: the logarithms' range is that of the ends'.)
        let (min, max) = if c.log10 {
            (min.log10(), max.log10())
        } else {
            (min, max)
        };
        infos.push(AttributeInfo {
            name: c.name.to_string(),
            min,
            max,
            log10: c.log10,
        });
    }
    let over: Vec<(&AttributeInfo, &[f32])> = infos
        .iter()
        .zip(columns)
        .map(|(i, c)| (i, c.values))
        .collect();
    Ok(extra_attributes_over(h, &over, species)?
        .into_iter()
        .map(|(e, _)| e)
        .collect())
}

/// The sums a node's mean is made of, over its particles: what the means of several
/// hierarchies' roots combine from (a chunked build's top node).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MeanSums {
    /// Sum of the particles' areas `r²`.
    pub area: f64,
    /// Sum of area × value.
    pub weighted: f64,
    /// Sum of the values (the plain mean's, where the areas sum to 0).
    pub plain: f64,
    pub count: u64,
}

impl MeanSums {
    /// The area-weighted mean (a plain mean where the areas sum to 0; 0 with no
    /// particles).
    pub fn mean(&self) -> f32 {
        if self.area > 0.0 {
            (self.weighted / self.area) as f32
        } else if self.count > 0 {
            (self.plain / self.count as f64) as f32
        } else {
            0.0
        }
    }

    /// These sums and `other`'s, in this order.
    pub fn and(self, other: MeanSums) -> MeanSums {
        MeanSums {
            area: self.area + other.area,
            weighted: self.weighted + other.weighted,
            plain: self.plain + other.plain,
            count: self.count + other.count,
        }
    }
}

/// As [`extra_attributes`], each column quantized over the range its entry gives
/// (a chunked build quantizes every chunk over the frame's range), with the sums of
/// the root's mean. The values are finite: [`extra_attributes`] and a chunked build's
/// partition check them first.
pub fn extra_attributes_over(
    h: &Hierarchy,
    columns: &[(&AttributeInfo, &[f32])],
    species: &[Species],
) -> Result<Vec<(ExtraAttribute, MeanSums)>, BuildError> {
    if columns.is_empty() {
        return Ok(Vec::new());
    }
    // Each particle's area as the hierarchy's representatives weigh it.
    let areas: Vec<f64> = (0..h.particle_order.len())
        .map(|k| {
            let r = match &h.radius {
                Some((q, r)) => r.decode(q[k]),
                None => species
                    .get(usize::from(h.species_index[k]))
                    .map_or(0.0, |s| s.radius),
            };
            f64::from(r * r)
        })
        .collect();
    let runs = particle_ranges(&h.levels, &h.nodes);
    columns
        .iter()
        .map(|(info, values)| extra_attribute(h, info, values, &areas, &runs))
        .collect()
}

/// The first value not above 0 of a column kept as its logarithm, as an error.
fn check_positive(name: &str, values: &[f32]) -> Result<(), BuildError> {
    match values.iter().position(|v| v.is_nan() || *v <= 0.0) {
        Some(index) => Err(BuildError::NotPositiveAttribute {
            name: name.to_string(),
            index,
            value: values[index],
        }),
        None => Ok(()),
    }
}

/// The first non-finite value, as an error.
fn check_finite(values: &[f32]) -> Result<(), BuildError> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(BuildError::NonFiniteAttribute {
            index,
            value: values[index],
        }),
        None => Ok(()),
    }
}

/// One column of [`extra_attributes_over`], with the particles' `areas` (in the file's
/// order) and the nodes' particle `runs`.
fn extra_attribute(
    h: &Hierarchy,
    info: &AttributeInfo,
    values: &[f32],
    areas: &[f64],
    runs: &[Range<u64>],
) -> Result<(ExtraAttribute, MeanSums), BuildError> {
    let ordered: Vec<f32> = h
        .particle_order
        .iter()
        .map(|&i| values[i as usize])
        .collect();
    // A column kept as its logarithm stores the logarithms, and its means are the
    // logarithms of the linear means (so that `10^mean` times a node's area is its
    // particles' light).
    let stored = |v: f32| if info.log10 { v.log10() } else { v };
    let mean_of = |s: &MeanSums| stored(s.mean());
    let quantized = ordered.iter().map(|&v| info.encode(stored(v))).collect();
    let sums_of = |r: &Range<u64>| {
        let run = r.start as usize..(r.end as usize).min(ordered.len());
        let mut s = MeanSums {
            count: run.len() as u64,
            ..MeanSums::default()
        };
        for k in run {
            let v = f64::from(ordered[k]);
            s.area += areas[k];
            s.weighted += areas[k] * v;
            s.plain += v;
        }
        s
    };
    // Each node's sums over its own particles (sums of a whole level's run would lose the
    // small values beside a large total), every level's nodes in parallel; the root's
    // (node 0, every particle) kept for a chunked build's top node.
    let root = runs.first().map(sums_of).unwrap_or_default();
    let node_means = std::iter::once(mean_of(&root))
        .chain(
            runs.get(1..)
                .unwrap_or_default()
                .par_iter()
                .map(|r| mean_of(&sums_of(r)))
                .collect::<Vec<f32>>(),
        )
        .take(runs.len())
        .collect();
    Ok((
        ExtraAttribute {
            info: info.clone(),
            values: quantized,
            node_means,
        },
        root,
    ))
}
