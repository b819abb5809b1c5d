//! Acceleration-structure types: build flags and modes, the geometry a build reads, and the
//! motu types builds and copies are recorded with ([`AsBuild`], [`AsGeometry`]; `conv.rs`
//! turns them into Vulkan structs, `build_sizes.rs` asks the device for their sizes).

use ash::vk;
/// Acceleration structures must start at multiples of 256 bytes in their buffer (spec:
/// `VkAccelerationStructureCreateInfoKHR::offset`).
pub const ACCELERATION_STRUCTURE_OFFSET_ALIGNMENT: u64 = 256;

/// Bytes per `VkAccelerationStructureInstanceKHR` in a TLAS instance buffer.
pub const INSTANCE_RECORD_SIZE_BYTES: u64 = 64;

/// One geometry of a bottom-level acceleration structure, described by its counts only.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BlasGeometry {
    /// Triangles with `f32 x3` positions (12-byte stride) and optional `u32` indices.
    Triangles {
        vertex_count: u32,
        triangle_count: u32,
        indexed: bool,
        opaque: bool,
    },
    /// Axis-aligned boxes (programmable instances, procedural primitives).
    Aabbs { aabb_count: u32, opaque: bool },
}

impl BlasGeometry {
    pub(crate) fn primitive_count(&self) -> u32 {
        match *self {
            BlasGeometry::Triangles { triangle_count, .. } => triangle_count,
            BlasGeometry::Aabbs { aabb_count, .. } => aabb_count,
        }
    }
}

/// Build flags that change sizes. The default is what motu builds: fast trace + compaction.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AsBuildFlags {
    pub prefer_fast_trace: bool,
    pub prefer_fast_build: bool,
    pub allow_compaction: bool,
    pub allow_update: bool,
    pub low_memory: bool,
}

impl AsBuildFlags {
    /// A TLAS's flags: fast trace, compaction allowed when it will be compacted (the size
    /// query and the build must agree).
    pub fn tlas(compact: bool) -> Self {
        TlasBuild::FastTrace.flags(compact)
    }
}

impl Default for AsBuildFlags {
    fn default() -> Self {
        Self {
            prefer_fast_trace: true,
            prefer_fast_build: false,
            allow_compaction: true,
            allow_update: false,
            low_memory: false,
        }
    }
}

/// How triangle BLASes (and the streamer's proxy boxes) are built: what the driver is asked
/// to favour. TLASes: [`TlasBuild`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum BlasBuild {
    /// Fast trace, compacted: the full build's default, where everything is resident once and
    /// the frame is all tracing.
    #[default]
    FastTrace,
    /// Fast build and low memory, compacted: streaming's default. On the H200 these BLASes
    /// are a fifth smaller (island 0.3: 79 against 99 bytes a triangle) and build faster, so
    /// more of a frame fits its room and a frame builds less; streaming frames are mostly
    /// building, not tracing (BENCHMARKS.md, session 17).
    Small,
}

impl BlasBuild {
    /// The build flags (the same for the size query and the build).
    pub fn flags(self) -> AsBuildFlags {
        match self {
            BlasBuild::FastTrace => AsBuildFlags::default(),
            BlasBuild::Small => AsBuildFlags {
                prefer_fast_trace: false,
                prefer_fast_build: true,
                low_memory: true,
                ..AsBuildFlags::default()
            },
        }
    }

    /// The name `--blas-build` takes and `--stats` reports.
    pub fn name(self) -> &'static str {
        match self {
            BlasBuild::FastTrace => "fast-trace",
            BlasBuild::Small => "small",
        }
    }
}

/// How TLASes are built: what the driver is asked to favour (`--stream-tlas-build` for the
/// streamer's rebuilt TLASes; the full build's and persistent TLASes are fast trace).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TlasBuild {
    /// Fast trace: the full build's, where a TLAS is built once and traced every frame.
    #[default]
    FastTrace,
    /// Fast build: a streamed TLAS is rebuilt whenever its resident instances change (tens of
    /// times a frame, millions of records each), and traced by a few passes only.
    FastBuild,
}

impl TlasBuild {
    /// The build flags, compaction allowed when the TLAS will be compacted (the same for the
    /// size query and the build).
    pub fn flags(self, compact: bool) -> AsBuildFlags {
        AsBuildFlags {
            prefer_fast_trace: self == TlasBuild::FastTrace,
            prefer_fast_build: self == TlasBuild::FastBuild,
            allow_compaction: compact,
            ..AsBuildFlags::default()
        }
    }

    /// The name `--stream-tlas-build` takes and `--stats` reports.
    pub fn name(self) -> &'static str {
        match self {
            TlasBuild::FastTrace => "fast-trace",
            TlasBuild::FastBuild => "fast-build",
        }
    }
}

/// Which level an acceleration structure is: a BLAS over geometry or a TLAS over instances.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AsLevel {
    Bottom,
    Top,
}

/// One geometry of a build, by the device addresses of its inputs (which the caller keeps
/// alive and written until the build's submission was waited on).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AsGeometry {
    /// Triangles: `vertex_count` `f32 x3` positions (12-byte stride) and `u32` indices.
    /// `opaque`: no any-hit; else each candidate reaches any-hit once.
    Triangles {
        positions_address: u64,
        vertex_count: u32,
        indices_address: u64,
        opaque: bool,
    },
    /// Axis-aligned boxes of 24 bytes (min xyz, max xyz) at `address`.
    Aabbs { address: u64, opaque: bool },
    /// A TLAS's instance records ([`INSTANCE_RECORD_SIZE_BYTES`] each) at `address`.
    Instances { address: u64 },
}

/// Whether a build makes a new structure or updates one in place.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AsBuildMode {
    Build,
    /// Refit the destination in place (it was built with `allow_update` over as many
    /// primitives; the spec allows source = destination).
    UpdateInPlace,
}

/// How an acceleration-structure copy treats its source.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AsCopyMode {
    /// Into a structure of the compacted size a query reported (source built with
    /// `allow_compaction`).
    Compact,
    /// A whole copy into a structure of the source's size (moving it to other memory).
    Clone,
}

/// Which hit group an instance's rays run and whether triangles are forced opaque.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InstanceHit {
    /// Triangles (hit group 0); `any_hit`: alpha-tested, so not forced opaque.
    Triangles { any_hit: bool },
    /// Programmable instances' boxes (hit group 1), never opaque.
    Procedural,
    /// A streamed TLAS's proxy boxes (hit group 2: their own intersection and any-hit
    /// shaders), never opaque.
    Proxy,
}

/// One structure to build into `dst`: `geometries[i]` holds `primitive_counts[i]` primitives;
/// its scratch starts at `scratch_address` (aligned to the device's scratch alignment).
#[derive(Clone, Copy, Debug)]
pub struct AsBuild<'g> {
    pub level: AsLevel,
    /// The flags the sizes were queried with.
    pub flags: AsBuildFlags,
    pub mode: AsBuildMode,
    pub dst: AsTarget,
    pub geometries: &'g [AsGeometry],
    pub primitive_counts: &'g [u32],
    pub scratch_address: u64,
}

/// An acceleration structure named in a recorded command without borrowing it (see
/// [`crate::CommandRecorder`]: its owner keeps it alive until the submission was waited on).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AsTarget(pub(crate) vk::AccelerationStructureKHR);

/// Worst-case sizes from `vkGetAccelerationStructureBuildSizesKHR` (before compaction).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AsBuildSizes {
    pub acceleration_structure_size_bytes: u64,
    pub build_scratch_size_bytes: u64,
    pub update_scratch_size_bytes: u64,
}

#[cfg(test)]
mod tests;
