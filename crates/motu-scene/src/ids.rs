//! Newtype ids: every cross-API index is typed, 32-bit, and never a bare `usize`.

macro_rules! id_type {
    ($(#[$doc:meta])* $name:ident) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
        #[derive(bytemuck::Pod, bytemuck::Zeroable, serde::Serialize, serde::Deserialize)]
        #[repr(transparent)]
        pub struct $name(pub u32);

        impl $name {
            /// The id as an index into the owning table.
            #[inline]
            pub fn index(self) -> usize {
                self.0 as usize
            }
        }

        impl std::fmt::Display for $name {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                write!(f, "{}#{}", stringify!($name), self.0)
            }
        }
    };
}

id_type!(
    /// A mesh of the imported scene; stable across compile settings (levels, splits, LOD).
    MeshId
);
id_type!(
    /// A prototype (instance definition); the root prototype is the world.
    PrototypeId
);
id_type!(
    /// A material.
    MaterialId
);
id_type!(
    /// A named camera.
    CameraId
);
id_type!(
    /// A light.
    LightId
);
id_type!(
    /// A top-level part of the scene (pbrt: a file included from the entry file's world block).
    ElementId
);
id_type!(
    /// An instance edge in the scene's CSR edge table.
    EdgeIndex
);
