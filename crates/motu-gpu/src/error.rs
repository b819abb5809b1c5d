use motu_vk::VkError;

/// Everything that can go wrong in the GPU scene, renderers and streaming: the device layer's
/// errors ([`VkError`], shown as they are) and the few this crate's own policy raises.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    /// A device-layer failure (its message unchanged).
    #[error(transparent)]
    Device(VkError),

    /// The VRAM budget or the allocation-count cap refused a request (what was asked, what is
    /// in use, the budget). The heap's refusals are lifted here from [`VkError::Budget`], so
    /// one pattern catches the heap's and the streamer's (callers evict and retry on it).
    #[error("VRAM budget: {0}")]
    Budget(String),

    #[error("invalid request: {0}")]
    InvalidRequest(String),

    #[error("{what}: {requested} requested, the limit in force is {limit}")]
    LimitExceeded {
        what: &'static str,
        requested: u64,
        limit: u64,
    },

    #[error(
        "no device supports {what}; devices and what they lack: {details}. Ray tracing needs \
         VK_KHR_acceleration_structure plus VK_KHR_ray_tracing_pipeline or VK_KHR_ray_query: on a \
         CPU use lavapipe from Mesa >= 24.1 (`tools/setup.sh`), on a GPU an RT-capable driver"
    )]
    MissingFeature { what: String, details: String },
}

impl From<VkError> for GpuError {
    fn from(e: VkError) -> GpuError {
        match e {
            // Policy above the device layer matches budget refusals (evict and retry).
            VkError::Budget(msg) => GpuError::Budget(msg),
            e => GpuError::Device(e),
        }
    }
}

pub type Result<T, E = GpuError> = std::result::Result<T, E>;
