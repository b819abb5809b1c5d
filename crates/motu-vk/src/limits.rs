//! Device limits later stages must respect, and test overrides that can only lower them.

use crate::error::{Result, SizeParseError, VkError};

/// Limits of one device, as motu uses them. Ray-tracing limits are 0 when the device lacks the
/// extension (check [`crate::Caps`] first). Values may be lowered by [`LimitOverrides`].
#[derive(Clone, Debug, PartialEq)]
pub struct Limits {
    /// Instances per TLAS (`VkPhysicalDeviceAccelerationStructurePropertiesKHR`).
    pub max_instance_count: u64,
    /// Triangles or AABBs per BLAS (summed over its geometries).
    pub max_primitive_count: u64,
    /// Geometries per BLAS.
    pub max_geometry_count: u64,
    /// Live `vkAllocateMemory` allocations; the context refuses allocations beyond it.
    pub max_memory_allocation_count: u32,
    /// Bytes per `vkAllocateMemory` (`VkPhysicalDeviceMaintenance3Properties`).
    pub max_memory_allocation_size: u64,
    /// Bytes one storage-buffer descriptor may cover.
    pub max_storage_buffer_range: u32,
    /// Bytes per `VkBuffer` (`VkPhysicalDeviceMaintenance4Properties`); `None` without maintenance4.
    pub max_buffer_size: Option<u64>,
    pub min_acceleration_structure_scratch_offset_alignment: u32,
    pub max_descriptor_set_acceleration_structures: u32,
    pub shader_group_handle_size: u32,
    pub shader_group_base_alignment: u32,
    pub shader_group_handle_alignment: u32,
    pub max_shader_group_stride: u32,
    pub max_ray_recursion_depth: u32,
    pub max_ray_hit_attribute_size: u32,
    pub max_ray_dispatch_invocation_count: u32,
    /// Nanoseconds per timestamp tick.
    pub timestamp_period_ns: f32,
    /// Valid bits of timestamps on the queue motu uses; 0 means no timestamps.
    pub timestamp_valid_bits: u32,
    pub max_push_constants_size: u32,
    pub max_compute_work_group_count: [u32; 3],
    pub max_compute_work_group_invocations: u32,
    pub min_storage_buffer_offset_alignment: u64,
    pub non_coherent_atom_size: u64,
}

impl Limits {
    /// The alignment of build scratch offsets in bytes: the device's minimum, as a power of
    /// two (at least 1), so sub-allocated scratch slices can be aligned with a mask.
    pub fn scratch_alignment_bytes(&self) -> u64 {
        u64::from(
            self.min_acceleration_structure_scratch_offset_alignment
                .max(1),
        )
        .next_power_of_two()
    }
}

/// Lowers limits for tests (e.g. a 4096-allocation driver simulated on lavapipe). Values above
/// the device's limit are ignored (with a warning): overrides never raise a limit.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LimitOverrides {
    pub max_memory_allocation_count: Option<u32>,
    pub max_memory_allocation_size: Option<u64>,
    pub max_instance_count: Option<u64>,
    pub max_primitive_count: Option<u64>,
    pub max_storage_buffer_range: Option<u32>,
}

/// Environment variables read by [`LimitOverrides::from_env`].
pub const ENV_MAX_ALLOCATIONS: &str = "MOTU_MAX_ALLOCATIONS";
pub const ENV_MAX_ALLOCATION_SIZE: &str = "MOTU_MAX_ALLOCATION_SIZE";
pub const ENV_MAX_INSTANCE_COUNT: &str = "MOTU_MAX_INSTANCE_COUNT";
pub const ENV_MAX_PRIMITIVE_COUNT: &str = "MOTU_MAX_PRIMITIVE_COUNT";
pub const ENV_MAX_STORAGE_BUFFER_RANGE: &str = "MOTU_MAX_STORAGE_BUFFER_RANGE";

impl LimitOverrides {
    /// Reads `MOTU_MAX_ALLOCATIONS`, `MOTU_MAX_ALLOCATION_SIZE`, `MOTU_MAX_INSTANCE_COUNT`,
    /// `MOTU_MAX_PRIMITIVE_COUNT` and `MOTU_MAX_STORAGE_BUFFER_RANGE`. Sizes accept `64MiB`-style
    /// suffixes; an unparsable value is an error rather than silently ignored.
    pub fn from_env() -> Result<Self> {
        Self::from_lookup(|name| std::env::var(name).ok())
    }

    /// Same as [`Self::from_env`] with an injectable lookup (tests must not mutate the process env).
    pub fn from_lookup(lookup: impl Fn(&str) -> Option<String>) -> Result<Self> {
        let get = |name: &'static str| -> Result<Option<u64>> {
            match lookup(name) {
                None => Ok(None),
                Some(v) if v.trim().is_empty() => Ok(None),
                Some(v) => parse_size(&v)
                    .map(Some)
                    .map_err(|source| VkError::InvalidEnvSize {
                        name,
                        value: v.clone(),
                        source,
                    }),
            }
        };
        let to_u32 = |name: &'static str, v: Option<u64>| -> Result<Option<u32>> {
            v.map(|v| {
                u32::try_from(v).map_err(|_| VkError::InvalidEnv {
                    name,
                    value: v.to_string(),
                    reason: "must fit in 32 bits".into(),
                })
            })
            .transpose()
        };
        Ok(Self {
            max_memory_allocation_count: to_u32(ENV_MAX_ALLOCATIONS, get(ENV_MAX_ALLOCATIONS)?)?,
            max_memory_allocation_size: get(ENV_MAX_ALLOCATION_SIZE)?,
            max_instance_count: get(ENV_MAX_INSTANCE_COUNT)?,
            max_primitive_count: get(ENV_MAX_PRIMITIVE_COUNT)?,
            max_storage_buffer_range: to_u32(
                ENV_MAX_STORAGE_BUFFER_RANGE,
                get(ENV_MAX_STORAGE_BUFFER_RANGE)?,
            )?,
        })
    }

    /// Field-wise minimum of two override sets (API and environment both apply).
    pub fn combine(&self, other: &Self) -> Self {
        fn min<T: Ord + Copy>(a: Option<T>, b: Option<T>) -> Option<T> {
            match (a, b) {
                (Some(a), Some(b)) => Some(a.min(b)),
                (a, b) => a.or(b),
            }
        }
        Self {
            max_memory_allocation_count: min(
                self.max_memory_allocation_count,
                other.max_memory_allocation_count,
            ),
            max_memory_allocation_size: min(
                self.max_memory_allocation_size,
                other.max_memory_allocation_size,
            ),
            max_instance_count: min(self.max_instance_count, other.max_instance_count),
            max_primitive_count: min(self.max_primitive_count, other.max_primitive_count),
            max_storage_buffer_range: min(
                self.max_storage_buffer_range,
                other.max_storage_buffer_range,
            ),
        }
    }

    pub fn is_empty(&self) -> bool {
        *self == Self::default()
    }

    /// Lowers `limits` in place; returns the names of the limits actually lowered.
    pub fn apply(&self, limits: &mut Limits) -> Vec<&'static str> {
        let mut lowered = Vec::new();
        lower(
            &mut limits.max_memory_allocation_count,
            self.max_memory_allocation_count,
            "max_memory_allocation_count",
            &mut lowered,
        );
        lower(
            &mut limits.max_memory_allocation_size,
            self.max_memory_allocation_size,
            "max_memory_allocation_size",
            &mut lowered,
        );
        lower(
            &mut limits.max_instance_count,
            self.max_instance_count,
            "max_instance_count",
            &mut lowered,
        );
        lower(
            &mut limits.max_primitive_count,
            self.max_primitive_count,
            "max_primitive_count",
            &mut lowered,
        );
        lower(
            &mut limits.max_storage_buffer_range,
            self.max_storage_buffer_range,
            "max_storage_buffer_range",
            &mut lowered,
        );
        lowered
    }
}

fn lower<T: Ord + Copy + std::fmt::Display>(
    value: &mut T,
    wanted: Option<T>,
    name: &'static str,
    lowered: &mut Vec<&'static str>,
) {
    let Some(wanted) = wanted else { return };
    if wanted < *value {
        *value = wanted;
        lowered.push(name);
    } else if wanted > *value {
        tracing::warn!(limit = name, wanted = %wanted, device = %value, "override above the device limit ignored");
    }
}

/// Parses `4096`, `64MiB`, `2GiB`, `512KiB`, `1GB` (decimal) into a count/bytes.
pub fn parse_size(text: &str) -> std::result::Result<u64, SizeParseError> {
    let t = text.trim();
    let split = t.find(|c: char| !c.is_ascii_digit()).unwrap_or(t.len());
    let (digits, suffix) = t.split_at(split);
    if digits.is_empty() {
        return Err(SizeParseError::NoNumber);
    }
    let n: u64 = digits.parse()?;
    let mul: u64 = match suffix.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1,
        "kib" | "k" => 1 << 10,
        "mib" | "m" => 1 << 20,
        "gib" | "g" => 1 << 30,
        "tib" | "t" => 1 << 40,
        "kb" => 1_000,
        "mb" => 1_000_000,
        "gb" => 1_000_000_000,
        "tb" => 1_000_000_000_000,
        other => return Err(SizeParseError::Unit(other.to_string())),
    };
    n.checked_mul(mul).ok_or(SizeParseError::Overflow)
}

#[cfg(test)]
mod tests;
