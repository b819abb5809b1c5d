//! Table slots: where each table's device address sits in the shaders' push constants.

/// Table slots in the shaders' push constants (`common.glsl`, same order).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(usize)]
pub(crate) enum Slot {
    Frame = 0,
    Tlases,
    Instances,
    Blases,
    Geometries,
    Pis,
    Selectors,
    LodLevels,
    Meshes,
    Materials,
    MeshGeo,
    TlasAddresses,
    Aov,
    Rgba,
    Stats,
    /// Streaming parameters (`stream.rs`); 0 outside streaming.
    Stream,
}

pub(crate) const SLOT_COUNT: usize = 16;
