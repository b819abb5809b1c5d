use motu_vk::{BudgetRefusal, VkError};

/// Why a [`crate::MeshBlobSource`] could not give a mesh (a package's chunk error, say): kept
/// as the cause of [`GpuError::MeshSource`].
pub type MeshSourceError = Box<dyn std::error::Error + Send + Sync>;

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
    Budget(BudgetRefusal),

    #[error("invalid request: {0}")]
    InvalidRequest(String),

    /// The hierarchy's tables refer out of range (checked before a build).
    #[error("invalid request: {0}")]
    Hierarchy(#[from] motu_abi::HierarchyError),

    /// The mesh source (a package's chunks) could not give mesh record `mesh_record`.
    #[error("invalid request: mesh record {mesh_record}: {source}")]
    MeshSource {
        mesh_record: usize,
        #[source]
        source: MeshSourceError,
    },

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

    /// A size source outside this crate failed (see [`GpuError::size_source`]).
    #[error(transparent)]
    SizeSource(Box<dyn std::error::Error + Send + Sync>),
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

impl GpuError {
    /// The mesh source's failure to give mesh record `mesh_record`, kept as the cause.
    pub(crate) fn mesh_source(mesh_record: usize) -> impl FnOnce(MeshSourceError) -> GpuError {
        move |source| GpuError::MeshSource {
            mesh_record,
            source,
        }
    }

    /// A size source outside this crate (an implementor of [`crate::FloorSizes`], e.g.
    /// `motu report`'s size model) failed: its error, kept as the cause.
    pub fn size_source(e: impl std::error::Error + Send + Sync + 'static) -> GpuError {
        GpuError::SizeSource(Box::new(e))
    }
}

pub type Result<T, E = GpuError> = std::result::Result<T, E>;
