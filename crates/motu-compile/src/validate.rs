//! Checks every constraint of a compiled hierarchy, whether it came from the compiler or from a
//! package: references, levels and parity, geometry kinds, caps, and bounds containment
//! through transforms (all 8 corners). Strictly increasing levels along every edge also prove
//! the graph acyclic.

use crate::finalize::{for_each_child, pi_target_bounds};
use crate::{xform, DEFAULT_MAX_PER_NODE};
use motu_abi::{HierarchyError, HierarchyView, BLAS_AABBS, BLAS_TRIANGLES};
use motu_scene::Aabb;

/// Device limits a hierarchy must respect.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    pub max_instances_per_tlas: u32,
    /// Checked for AABB BLASes and for triangle BLASes of several meshes (one mesh over the
    /// cap cannot be split by the compiler; it is reported when compiled).
    pub max_primitives_per_blas: u32,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            max_instances_per_tlas: DEFAULT_MAX_PER_NODE,
            max_primitives_per_blas: DEFAULT_MAX_PER_NODE,
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ValidateError {
    #[error(transparent)]
    References(#[from] HierarchyError),
    #[error("{node}: level {level} has the wrong parity (TLAS even, BLAS odd, root 0)")]
    Parity { node: String, level: u32 },
    #[error("{parent} (level {parent_level}) → {child} (level {child_level}): a child's level must exceed its parent's (a cycle, or stale levels)")]
    Order {
        parent: String,
        parent_level: u32,
        child: String,
        child_level: u32,
    },
    #[error("{node}: {count} over the cap of {cap}")]
    Cap { node: String, count: u64, cap: u32 },
    #[error("{node}: {reason}")]
    Kind { node: String, reason: String },
    #[error("{node}: bounds {outer:?} do not contain {what} {inner:?}")]
    Containment {
        node: String,
        what: String,
        outer: Aabb,
        inner: Aabb,
    },
}

/// [`validate_with`] the Vulkan-safe default limits.
pub fn validate(view: &HierarchyView<'_>) -> Result<(), ValidateError> {
    validate_with(view, &Limits::default())
}

fn name(nt: usize, node: usize) -> String {
    if node < nt {
        format!("TLAS {node}")
    } else {
        format!("BLAS {}", node - nt)
    }
}

/// `outer ⊇ inner` with a tolerance relative to the coordinates' magnitude.
fn contains(outer: &Aabb, inner: &Aabb) -> bool {
    if inner.is_empty() {
        return true;
    }
    let scale = outer
        .min
        .iter()
        .chain(&outer.max)
        .chain(&inner.min)
        .chain(&inner.max)
        .fold(1.0f32, |m, v| m.max(v.abs()));
    outer.contains(inner, scale * 1e-5)
}

pub fn validate_with(view: &HierarchyView<'_>, limits: &Limits) -> Result<(), ValidateError> {
    let _span = tracing::debug_span!("validate").entered();
    view.check_references()?;
    let nt = view.tlases.len();
    let n = nt + view.blases.len();
    let level = |node: usize| {
        if node < nt {
            view.tlases[node].level
        } else {
            view.blases[node - nt].level
        }
    };
    let bounds = |node: usize| {
        if node < nt {
            let t = &view.tlases[node];
            xform::aabb_from_record(t.bounds_min, t.bounds_max)
        } else {
            let b = &view.blases[node - nt];
            xform::aabb_from_record(b.bounds_min, b.bounds_max)
        }
    };
    if view.tlases[view.root_tlas as usize].level != 0 {
        return Err(ValidateError::Parity {
            node: name(nt, view.root_tlas as usize),
            level: view.tlases[view.root_tlas as usize].level,
        });
    }
    for node in 0..n {
        let l = level(node);
        if (l % 2 == 0) != (node < nt) {
            return Err(ValidateError::Parity {
                node: name(nt, node),
                level: l,
            });
        }
        let mut bad = None;
        for_each_child(view, node, |c| {
            if bad.is_none() && level(c) <= l {
                bad = Some(c);
            }
        });
        if let Some(c) = bad {
            return Err(ValidateError::Order {
                parent: name(nt, node),
                parent_level: l,
                child: name(nt, c),
                child_level: level(c),
            });
        }
    }

    for (i, t) in view.tlases.iter().enumerate() {
        if t.instance_count > limits.max_instances_per_tlas {
            return Err(ValidateError::Cap {
                node: name(nt, i),
                count: t.instance_count.into(),
                cap: limits.max_instances_per_tlas,
            });
        }
        let outer = bounds(i);
        let range = t.instance_range();
        for (k, inst) in view.instances[range].iter().enumerate() {
            let inner = bounds(nt + inst.blas as usize)
                .transformed(&xform::from_array(&inst.tlas_from_blas));
            if !contains(&outer, &inner) {
                return Err(ValidateError::Containment {
                    node: name(nt, i),
                    what: format!("instance {k} (BLAS {})", inst.blas),
                    outer,
                    inner,
                });
            }
        }
    }

    for (i, b) in view.blases.iter().enumerate() {
        let node = name(nt, nt + i);
        let kind_err = |reason: String| ValidateError::Kind {
            node: node.clone(),
            reason,
        };
        if b.item_count == 0 {
            return Err(kind_err("empty BLAS".into()));
        }
        let outer = bounds(nt + i);
        let range = b.item_base as usize..(b.item_base + b.item_count) as usize;
        match b.kind {
            BLAS_TRIANGLES => {
                let mut tris = 0u64;
                for g in &view.geometries[range] {
                    let m = &view.meshes[g.mesh as usize];
                    tris += u64::from(m.triangle_count);
                    let inner = xform::aabb_from_record(m.bounds_min, m.bounds_max);
                    if !contains(&outer, &inner) {
                        return Err(ValidateError::Containment {
                            node,
                            what: format!("mesh record {}", g.mesh),
                            outer,
                            inner,
                        });
                    }
                }
                if tris != u64::from(b.primitive_count) {
                    return Err(kind_err(format!(
                        "primitive count {} but its meshes have {tris} triangles",
                        b.primitive_count
                    )));
                }
                if b.item_count > 1 && tris > u64::from(limits.max_primitives_per_blas) {
                    return Err(ValidateError::Cap {
                        node,
                        count: tris,
                        cap: limits.max_primitives_per_blas,
                    });
                }
            }
            BLAS_AABBS => {
                if b.primitive_count != b.item_count {
                    return Err(kind_err(format!(
                        "{} AABBs but primitive count {}",
                        b.item_count, b.primitive_count
                    )));
                }
                if b.item_count > limits.max_primitives_per_blas {
                    return Err(ValidateError::Cap {
                        node,
                        count: b.item_count.into(),
                        cap: limits.max_primitives_per_blas,
                    });
                }
                for k in range {
                    let pi = &view.pis[k];
                    let aabb = xform::aabb_from_record(pi.aabb_min, pi.aabb_max);
                    if !contains(&outer, &aabb) {
                        return Err(ValidateError::Containment {
                            node,
                            what: format!("PI {k}"),
                            outer,
                            inner: aabb,
                        });
                    }
                    let target = pi_target_bounds(view, bounds, pi).ok_or_else(|| {
                        kind_err(format!("PI {k}: child_from_parent is not invertible"))
                    })?;
                    if !contains(&aabb, &target) {
                        return Err(ValidateError::Containment {
                            node: format!("PI {k}"),
                            what: format!("its target (kind {}, {})", pi.kind, pi.target),
                            outer: aabb,
                            inner: target,
                        });
                    }
                }
            }
            other => return Err(kind_err(format!("unknown kind {other}"))),
        }
    }
    Ok(())
}
