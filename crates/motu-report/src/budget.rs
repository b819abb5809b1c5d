//! What fits a VRAM budget: each element alone, the best subset, the variants, streaming.
//!
//! The subset suggestion maximises **instanced triangles** (visible geometry after
//! flattening) under `peak_bytes ≤ budget`, where a subset's cost counts its owned nodes, every
//! shared node any member uses (once), its own root TLAS and the global tables. With at most
//! [`EXACT_LIMIT`] elements every subset is tried (exact); above, a greedy pass adds the
//! element with the most triangles per marginal byte while it fits, and the best single
//! element replaces it when that is better (the classic ½-approximation fix for greedy
//! knapsack).

use std::collections::BTreeMap;

use serde::Serialize;

use crate::cost::{tlas_cost, Cost};
use crate::rows::{ElementReport, VariantReport};
use crate::sizes::SizeSource;
use crate::ReportError;

/// Subsets are enumerated exactly up to this many elements.
pub const EXACT_LIMIT: usize = 12;

/// Costs any subset of elements (labels as in the report).
pub(crate) struct SubsetCoster {
    pub owned: BTreeMap<u32, Cost>,
    pub root_count: BTreeMap<u32, u64>,
    /// Shared nodes grouped by the (sorted) set of elements using them.
    pub groups: Vec<(Vec<u32>, Cost)>,
    pub global: Cost,
    /// Labels every subset includes (untagged root instances).
    pub forced: Vec<u32>,
    pub table_bytes_per_root_instance: u64,
    /// The image a subset renders at (its cost includes the full build's overhead there).
    pub image: (u32, u32),
    /// The record tables `--subset` uploads whole (`motu_abi::RootSubset` keeps only the
    /// instance and PI records its root reaches, and every TLAS, BLAS, geometry, mesh and LOD
    /// record, plus the filtered root's TLAS record). Added to a subset's own records: the
    /// members' few small records count twice, a conservative error.
    pub whole_table_bytes: u64,
}

impl SubsetCoster {
    pub fn cost(&self, subset: &[u32], sizes: &dyn SizeSource) -> Result<Cost, ReportError> {
        let mut members: Vec<u32> = subset.iter().chain(&self.forced).copied().collect();
        members.sort_unstable();
        members.dedup();
        let mut c = self.global;
        let mut n_root = 0u64;
        for l in &members {
            if let Some(o) = self.owned.get(l) {
                c.add(o);
            }
            n_root += self.root_count.get(l).copied().unwrap_or(0);
        }
        for (set, g) in &self.groups {
            if set.iter().any(|e| members.binary_search(e).is_ok()) {
                c.add(g);
            }
        }
        let (mut root, _) = tlas_cost(sizes, n_root)?;
        root.table_bytes += self.table_bytes_per_root_instance;
        root.seal();
        c.add(&root);
        c.table_bytes += self.whole_table_bytes;
        c.seal();
        Ok(c.rendered_at(self.image))
    }
}

/// Whether one thing fits.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Fit {
    pub name: String,
    pub peak_bytes: u64,
    pub fits: bool,
}

/// The suggested subset.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SubsetSuggestion {
    pub elements: Vec<String>,
    /// Ready to paste: `--subset a,b,c`.
    pub subset_arg: String,
    pub cost: Cost,
    pub instanced_triangles: u64,
    /// Of the whole scene's instanced triangles.
    pub triangle_fraction: f64,
    /// `exact` or `greedy`.
    pub method: String,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BudgetReport {
    pub budget_bytes: u64,
    /// The whole scene as compiled fits (peak).
    pub scene_fits: bool,
    pub variants: Vec<Fit>,
    /// Each element rendered alone.
    pub elements: Vec<Fit>,
    /// `None` when no element fits alone.
    pub suggestion: Option<SubsetSuggestion>,
    /// Per-BLAS streaming's floor (see `StreamingReport`) fits.
    pub streaming_fits: bool,
    pub notes: Vec<String>,
}

pub(crate) fn plan_budget(
    budget: u64,
    coster: &SubsetCoster,
    elements: &[ElementReport],
    variants: &[VariantReport],
    sizes: &dyn SizeSource,
    name_of: &dyn Fn(u32) -> String,
    streaming_min_bytes: u64,
) -> Result<BudgetReport, ReportError> {
    let _span = tracing::info_span!("report_budget", budget_bytes = budget).entered();
    let variant_fits: Vec<Fit> = variants
        .iter()
        .map(|v| Fit {
            name: v.name.clone(),
            peak_bytes: v.cost.peak_bytes,
            fits: v.cost.peak_bytes <= budget,
        })
        .collect();
    let scene_fits = variant_fits.first().is_some_and(|v| v.fits);
    let element_fits: Vec<Fit> = elements
        .iter()
        .filter(|e| e.kind == "element")
        .filter_map(|e| {
            e.alone.map(|a| Fit {
                name: e.name.clone(),
                peak_bytes: a.peak_bytes,
                fits: a.peak_bytes <= budget,
            })
        })
        .collect();
    let value: BTreeMap<u32, u64> = elements
        .iter()
        .filter(|e| e.kind == "element" && e.root_instances > 0)
        .filter_map(|e| e.id.map(|id| (id, e.instanced_triangles)))
        .collect();
    let candidates: Vec<u32> = value.keys().copied().collect();
    let total_value: u64 = elements.iter().map(|e| e.instanced_triangles).sum();
    let mut notes = Vec::new();
    let val = |s: &[u32]| {
        s.iter()
            .map(|l| value.get(l).copied().unwrap_or(0))
            .sum::<u64>()
    };

    let (best, method) = if candidates.len() <= EXACT_LIMIT {
        let mut best: Option<(u64, u64, Vec<u32>)> = None;
        for mask in 1u32..(1u32 << candidates.len()) {
            let s: Vec<u32> = candidates
                .iter()
                .enumerate()
                .filter(|(i, _)| mask & (1 << i) != 0)
                .map(|(_, &l)| l)
                .collect();
            let c = coster.cost(&s, sizes)?;
            if c.peak_bytes > budget {
                continue;
            }
            let v = val(&s);
            let better = match &best {
                None => true,
                Some((bv, bp, _)) => v > *bv || (v == *bv && c.peak_bytes < *bp),
            };
            if better {
                best = Some((v, c.peak_bytes, s));
            }
        }
        (best.map(|b| b.2), "exact")
    } else {
        let mut chosen: Vec<u32> = Vec::new();
        let mut current = coster.cost(&[], sizes)?.peak_bytes;
        loop {
            let mut pick: Option<(f64, u32, u64)> = None;
            for &l in candidates.iter().filter(|l| !chosen.contains(l)) {
                let mut s = chosen.clone();
                s.push(l);
                let peak = coster.cost(&s, sizes)?.peak_bytes;
                if peak > budget {
                    continue;
                }
                let ratio = value.get(&l).copied().unwrap_or(0) as f64
                    / peak.saturating_sub(current).max(1) as f64;
                if pick.is_none_or(|p| ratio > p.0) {
                    pick = Some((ratio, l, peak));
                }
            }
            let Some((_, l, peak)) = pick else { break };
            chosen.push(l);
            current = peak;
        }
        let single = candidates
            .iter()
            .copied()
            .filter(|&l| {
                coster
                    .cost(&[l], sizes)
                    .is_ok_and(|c| c.peak_bytes <= budget)
            })
            .max_by_key(|l| value.get(l).copied().unwrap_or(0));
        let best = match single {
            Some(l) if val(&[l]) > val(&chosen) => vec![l],
            _ => chosen,
        };
        ((!best.is_empty()).then_some(best), "greedy")
    };
    let suggestion = match best {
        Some(mut s) => {
            s.sort_unstable();
            let cost = coster.cost(&s, sizes)?;
            let names: Vec<String> = s.iter().map(|&l| name_of(l)).collect();
            let v = val(&s);
            Some(SubsetSuggestion {
                subset_arg: format!("--subset {}", names.join(",")),
                elements: names,
                cost,
                instanced_triangles: v,
                triangle_fraction: if total_value == 0 {
                    0.0
                } else {
                    v as f64 / total_value as f64
                },
                method: method.into(),
            })
        }
        None => {
            notes.push(format!(
                "no element fits {} alone; consider streaming or a smaller element split",
                crate::human::human_bytes(budget)
            ));
            None
        }
    };
    if scene_fits {
        notes.push("the whole scene fits as compiled".into());
    }
    if !coster.forced.is_empty() {
        notes.push("untagged root instances are always included".into());
    }
    let streaming_fits = streaming_min_bytes <= budget;
    Ok(BudgetReport {
        budget_bytes: budget,
        scene_fits,
        variants: variant_fits,
        elements: element_fits,
        suggestion,
        streaming_fits,
        notes,
    })
}
