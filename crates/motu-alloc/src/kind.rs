//! What an allocation is for, which memory it lives in, and the ids handed out.

use std::fmt;

/// What an allocation holds; used for per-kind accounting only (alignment comes from the caller).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum AllocKind {
    /// Bottom-level acceleration structure storage (offset alignment 256).
    BlasStorage,
    /// Top-level acceleration structure storage (offset alignment 256).
    TlasStorage,
    /// Build scratch (`minAccelerationStructureScratchOffsetAlignment`).
    Scratch,
    /// TLAS instance buffers.
    InstanceBuffer,
    /// Vertex, index and AABB buffers.
    Geometry,
    /// Traversal node tables read by the traversal shader.
    NodeTable,
    /// Host-visible staging for uploads.
    Staging,
    /// Image textures and per-vertex shading attributes (normals, texture coordinates).
    Texture,
    /// Anything else.
    Other,
}

impl AllocKind {
    /// Every kind, in declaration order (the index used by per-kind tables).
    pub const ALL: [AllocKind; 9] = [
        AllocKind::BlasStorage,
        AllocKind::TlasStorage,
        AllocKind::Scratch,
        AllocKind::InstanceBuffer,
        AllocKind::Geometry,
        AllocKind::NodeTable,
        AllocKind::Staging,
        AllocKind::Texture,
        AllocKind::Other,
    ];

    pub(crate) fn index(self) -> usize {
        self as usize
    }

    /// The snake_case name used in reports.
    pub fn name(self) -> &'static str {
        match self {
            AllocKind::BlasStorage => "blas_storage",
            AllocKind::TlasStorage => "tlas_storage",
            AllocKind::Scratch => "scratch",
            AllocKind::InstanceBuffer => "instance_buffer",
            AllocKind::Geometry => "geometry",
            AllocKind::NodeTable => "node_table",
            AllocKind::Staging => "staging",
            AllocKind::Texture => "texture",
            AllocKind::Other => "other",
        }
    }
}

impl fmt::Display for AllocKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Which memory a block lives in. Each class is a separate pool of blocks; all pools share the
/// allocation-count cap.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum MemoryClass {
    /// `DEVICE_LOCAL` memory: acceleration structures, scratch, geometry, tables.
    DeviceLocal,
    /// `HOST_VISIBLE | HOST_COHERENT` memory: staging and readback.
    HostVisible,
}

impl MemoryClass {
    /// Every class, in declaration order.
    pub const ALL: [MemoryClass; 2] = [MemoryClass::DeviceLocal, MemoryClass::HostVisible];

    pub(crate) fn index(self) -> usize {
        self as usize
    }

    /// The snake_case name used in reports.
    pub fn name(self) -> &'static str {
        match self {
            MemoryClass::DeviceLocal => "device_local",
            MemoryClass::HostVisible => "host_visible",
        }
    }
}

impl fmt::Display for MemoryClass {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A memory block: one future `VkDeviceMemory`. Never reused within one allocator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct BlockId(pub u32);

impl fmt::Display for BlockId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "block {}", self.0)
    }
}

/// One live sub-allocation. Never reused within one allocator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct AllocationId(pub u64);

impl fmt::Display for AllocationId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "allocation {}", self.0)
    }
}

/// A byte count displayed as `N bytes (X.Y MiB)` in messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ByteSize(pub u64);

impl fmt::Display for ByteSize {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mib = self.0 as f64 / (1u64 << 20) as f64;
        write!(f, "{} bytes ({mib:.1} MiB)", self.0)
    }
}

/// The binary units byte sizes are printed in, smallest first.
pub const BINARY_UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];

/// `bytes` in the largest of [`BINARY_UNITS`] it reaches (at most TiB): the scaled value and
/// the unit. Every byte printer (`human_bytes`, `format_size`, the GPU report) rounds this.
pub fn binary_scale(bytes: u64) -> (f64, &'static str) {
    let mut v = bytes as f64;
    let mut u = 0;
    while v >= 1024.0 && u + 1 < BINARY_UNITS.len() {
        v /= 1024.0;
        u += 1;
    }
    (v, BINARY_UNITS[u])
}

/// `1536` → `1.5 KiB`: one decimal at every unit (the command line's progress, summaries and
/// error messages).
pub fn format_size(bytes: u64) -> String {
    match binary_scale(bytes) {
        (_, "B") => format!("{bytes} B"),
        (v, unit) => format!("{v:.1} {unit}"),
    }
}

#[cfg(test)]
mod tests;
