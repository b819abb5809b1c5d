//! LOD mode selection: instance-level LOD where the rule allows it, else the traversal shader.

use crate::RenderError;
use motu_abi::lod::LodParams;
use motu_abi::lod_instance::{rule_is_camera_only, InstanceLod};
use motu_abi::HierarchyView;

/// What `--lod-mode` asks for.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LodMode {
    /// Instance-level LOD where it applies (the default).
    #[default]
    Instance,
    /// Always in the traversal shader.
    Traversal,
}

/// How LOD runs for a frame: instance-level (a per-frame pass picks each instance's level and
/// the TLASes are rebuilt; one trace) or in the traversal shader, and why.
#[derive(Clone, Debug)]
pub struct LodChoice {
    pub instance: Option<InstanceLod>,
    /// `instance`, `traversal` or `none` (no LOD selectors).
    pub mode: &'static str,
    pub reason: &'static str,
    /// Programmable instances that are LOD selectors in the package.
    pub selector_pis: u32,
}

/// Instance-level LOD where the rule allows it; otherwise the traversal path, and why
/// (`motu render` and `motu view` decide alike).
pub fn choose_lod_mode(
    view: &HierarchyView<'_>,
    lod: &LodParams,
    mode: LodMode,
    stream: bool,
) -> Result<LodChoice, RenderError> {
    let selector_pis = view
        .pis
        .iter()
        .filter(|p| p.kind == motu_abi::PI_LOD_SELECTOR)
        .count() as u32;
    let traversal = |reason| LodChoice {
        instance: None,
        mode: "traversal",
        reason,
        selector_pis,
    };
    Ok(if selector_pis == 0 {
        LodChoice {
            instance: None,
            mode: "none",
            reason: "the package has no LOD selectors",
            selector_pis,
        }
    } else if mode == LodMode::Traversal {
        traversal("--lod-mode traversal")
    } else if !rule_is_camera_only(lod) {
        traversal("--lod-stochastic chooses a level per ray")
    } else if stream {
        traversal(
            "--stream resolves LOD in the traversal shader (instance LOD needs its levels' BLASes resident before the frame)",
        )
    } else {
        match InstanceLod::new(view).map_err(RenderError::InstanceLod)? {
            Some(il) => LodChoice {
                instance: Some(il),
                mode: "instance",
                reason: "the LOD rule depends only on the camera",
                selector_pis,
            },
            None => {
                traversal("no LOD selector qualifies (each sits in a TLAS placed more than once)")
            }
        }
    })
}

#[cfg(test)]
mod tests;
