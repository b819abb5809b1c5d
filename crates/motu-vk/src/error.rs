use ash::vk;

/// Everything that can go wrong in the device layer. Messages say what is missing and what to do.
///
/// `motu-gpu` wraps it in its `GpuError` (`#[error(transparent)]`: messages unchanged).
#[derive(Debug, thiserror::Error)]
pub enum VkError {
    #[error(
        "cannot load the Vulkan loader (libvulkan.so.1): {reason}. Install the loader \
         (Debian: `libvulkan1`) and a driver: for a CPU device run `tools/setup.sh`, which installs \
         `mesa-vulkan-drivers` (lavapipe, Mesa >= 24.1 for ray tracing) from bookworm-backports; \
         on NVIDIA install `libvulkan1` and set `VK_DRIVER_FILES` to the driver's `nvidia_icd.json`"
    )]
    LoaderMissing {
        #[source]
        reason: LoaderFault,
    },

    #[error(
        "no Vulkan device found. The loader works but no driver (ICD) reported a device: install \
         `mesa-vulkan-drivers` (run `tools/setup.sh`) or your GPU's Vulkan driver; on NVIDIA set \
         `VK_DRIVER_FILES` to the driver's `nvidia_icd.json`"
    )]
    NoDevice,

    #[error(
        "device index {index} does not exist: {count} Vulkan device(s) found (see `motu devices`)"
    )]
    DeviceIndexOutOfRange { index: usize, count: usize },

    #[error("device {index} ({name}) is not usable: {reason}")]
    DeviceUnsuitable {
        index: usize,
        name: String,
        reason: String,
    },

    #[error(
        "no device supports {what}; devices and what they lack: {details}. Ray tracing needs \
         VK_KHR_acceleration_structure plus VK_KHR_ray_tracing_pipeline or VK_KHR_ray_query: on a \
         CPU use lavapipe from Mesa >= 24.1 (`tools/setup.sh`), on a GPU an RT-capable driver"
    )]
    MissingFeature { what: String, details: String },

    /// The window system's surface extensions are unknown to the loader (`motu view`).
    #[error(
        "no device supports a Vulkan surface for this window system; devices and what they lack: \
         {source:?}. Ray tracing needs VK_KHR_acceleration_structure plus \
         VK_KHR_ray_tracing_pipeline or VK_KHR_ray_query: on a CPU use lavapipe from Mesa >= 24.1 \
         (`tools/setup.sh`), on a GPU an RT-capable driver"
    )]
    NoSurface {
        #[source]
        source: vk::Result,
    },

    #[error(
        "validation was forced on (MOTU_VALIDATION=1) but the layer VK_LAYER_KHRONOS_validation \
         is not installed (Debian: `vulkan-validationlayers`)"
    )]
    ValidationLayerMissing,

    #[error("{count} Vulkan validation error(s); first: {first}")]
    Validation { count: usize, first: String },

    #[error("invalid value {value:?} for environment variable {name}: {reason}")]
    InvalidEnv {
        name: &'static str,
        value: String,
        reason: String,
    },

    /// An environment variable holding a size that does not parse.
    #[error("invalid value {value:?} for environment variable {name}: {source}")]
    InvalidEnvSize {
        name: &'static str,
        value: String,
        #[source]
        source: SizeParseError,
    },

    #[error("invalid request: allocation limits: {0}")]
    AllocatorLimits(#[source] motu_alloc::LimitsError),

    #[error(
        "device memory allocation #{requested} refused: the allocation count limit is {limit} \
         (maxMemoryAllocationCount, possibly lowered by MOTU_MAX_ALLOCATIONS); \
         sub-allocate from larger blocks"
    )]
    AllocationCountExceeded { requested: u32, limit: u32 },

    #[error(
        "device memory allocation of {size_bytes} bytes exceeds the per-allocation limit of \
         {limit_bytes} bytes (maxMemoryAllocationSize, possibly lowered by MOTU_MAX_ALLOCATION_SIZE)"
    )]
    AllocationTooLarge { size_bytes: u64, limit_bytes: u64 },

    #[error("no memory type is suitable for {location:?} (allowed type bits {type_bits:#b})")]
    NoMemoryType {
        location: crate::MemoryLocation,
        type_bits: u32,
    },

    #[error("{what}: {requested} requested, the limit in force is {limit}")]
    LimitExceeded {
        what: &'static str,
        requested: u64,
        limit: u64,
    },

    /// The VRAM budget or the allocation-count cap refused a request (what was asked, what is
    /// in use, the budget).
    #[error("VRAM budget: {0}")]
    Budget(BudgetRefusal),

    #[error("invalid request: {0}")]
    InvalidRequest(String),

    #[error(
        "the GPU device was lost (VK_ERROR_DEVICE_LOST) during phase {phase:?}: the driver reset \
         the device (a shader fault or a timeout); the last submitted work was that phase"
    )]
    DeviceLost { phase: String },

    #[error("{call} failed: {result}")]
    Vulkan {
        call: &'static str,
        result: vk::Result,
    },
}

/// A refusal by the VRAM budget or the allocation-count cap: what was asked (a buffer's label,
/// or the streamer's words for its own policy) and, where the allocator refused, its typed
/// cause (shown after the words, and kept as the error's source).
#[derive(Debug)]
pub struct BudgetRefusal {
    what: String,
    cause: Option<Box<dyn std::error::Error + Send + Sync>>,
    /// Shown `what (cause)` rather than `what: cause` (see [`BudgetRefusal::explained`]).
    cause_in_parentheses: bool,
}

impl BudgetRefusal {
    /// A refusal in the caller's words alone (a policy above the allocator).
    pub fn new(what: impl Into<String>) -> BudgetRefusal {
        BudgetRefusal {
            what: what.into(),
            cause: None,
            cause_in_parentheses: false,
        }
    }

    /// `what` (a label) refused by `cause`; shown `what: cause`, or `cause` where `what` is
    /// empty.
    pub fn caused(
        what: impl Into<String>,
        cause: impl std::error::Error + Send + Sync + 'static,
    ) -> BudgetRefusal {
        BudgetRefusal {
            what: what.into(),
            cause: Some(Box::new(cause)),
            cause_in_parentheses: false,
        }
    }

    /// A refusal shown as its cause alone.
    pub fn from_cause(cause: impl std::error::Error + Send + Sync + 'static) -> BudgetRefusal {
        BudgetRefusal::caused(String::new(), cause)
    }

    /// This refusal explained in a policy's words (what does not fit, what to raise): shown
    /// `words (this refusal)`, this refusal kept as the cause.
    pub fn explained(self, words: impl Into<String>) -> BudgetRefusal {
        BudgetRefusal {
            what: words.into(),
            cause: Some(Box::new(self)),
            cause_in_parentheses: true,
        }
    }
}

impl From<String> for BudgetRefusal {
    fn from(what: String) -> BudgetRefusal {
        BudgetRefusal::new(what)
    }
}

impl std::fmt::Display for BudgetRefusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.cause {
            Some(cause) if self.what.is_empty() => write!(f, "{cause}"),
            Some(cause) if self.cause_in_parentheses => write!(f, "{} ({cause})", self.what),
            Some(cause) => write!(f, "{}: {cause}", self.what),
            None => f.write_str(&self.what),
        }
    }
}

impl std::error::Error for BudgetRefusal {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        self.cause
            .as_deref()
            .map(|c| c as &(dyn std::error::Error + 'static))
    }
}

/// Why the Vulkan loader is not usable.
#[derive(Debug, thiserror::Error)]
pub enum LoaderFault {
    /// `libvulkan.so.1` could not be loaded.
    #[error(transparent)]
    Load(#[from] ash::LoadingError),
    /// The loader is older than Vulkan 1.2.
    #[error("the loader supports only Vulkan {0}; motu needs 1.2 or newer")]
    TooOld(String),
}

impl VkError {
    /// A failed submission or wait of the phase `label` (device loss names the phase).
    pub(crate) fn from_submit(call: &'static str, result: vk::Result, label: &str) -> VkError {
        if result == vk::Result::ERROR_DEVICE_LOST {
            VkError::DeviceLost {
                phase: label.to_string(),
            }
        } else {
            VkError::Vulkan { call, result }
        }
    }

    pub(crate) fn vk(call: &'static str) -> impl FnOnce(vk::Result) -> VkError {
        move |result| VkError::Vulkan { call, result }
    }
}

/// The device layer's result.
pub type Result<T, E = VkError> = std::result::Result<T, E>;

/// Why a size (`64MiB`) does not parse.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SizeParseError {
    #[error("expected a number, optionally with a KiB/MiB/GiB/KB/MB/GB suffix")]
    NoNumber,
    #[error(transparent)]
    Digits(#[from] std::num::ParseIntError),
    #[error("unknown unit suffix {0:?}")]
    Unit(String),
    #[error("value overflows 64 bits")]
    Overflow,
}
