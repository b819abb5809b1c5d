//! GLSL mirror of the records: generated from one table of fields per struct, with each field's
//! Rust offset taken by `offset_of!`, so a test can prove the std430 layout GLSL computes equals
//! the Rust layout.

use crate::aov::AovRecord;
use crate::camera::CameraParams;
use crate::lod::LodParams;
use crate::lod_instance::LodSlotRecord;
use crate::tlas_compact::{
    TlasCompactPush, TLAS_COMPACT_CHUNK, TLAS_COMPACT_GROUP, TLAS_COMPACT_PER_THREAD,
};
use crate::*;
use std::mem::{offset_of, size_of};

/// A GLSL field type with its std430 (size, alignment).
#[derive(Clone, Copy, Debug)]
pub enum GlslType {
    Uint,
    Int,
    Float,
    Vec3,
    /// A u64 as `uvec2` (no int64 extension needed).
    U64,
    FloatArray(usize),
    UintArray(usize),
}

impl GlslType {
    fn decl(&self, name: &str) -> String {
        match self {
            Self::Uint => format!("uint {name};"),
            Self::Int => format!("int {name};"),
            Self::Float => format!("float {name};"),
            Self::Vec3 => format!("vec3 {name};"),
            Self::U64 => format!("uvec2 {name};"),
            Self::FloatArray(n) => format!("float {name}[{n}];"),
            Self::UintArray(n) => format!("uint {name}[{n}];"),
        }
    }

    /// (size, alignment) under std430.
    fn std430(&self) -> (usize, usize) {
        match self {
            Self::Uint | Self::Int | Self::Float => (4, 4),
            Self::Vec3 => (12, 16),
            Self::U64 => (8, 8),
            Self::FloatArray(n) | Self::UintArray(n) => (4 * n, 4),
        }
    }
}

pub struct StructDef {
    pub name: &'static str,
    pub size: usize,
    /// (type, name, Rust offset).
    pub fields: Vec<(GlslType, &'static str, usize)>,
}

macro_rules! def {
    ($ty:ty, [$(($gt:expr, $f:ident)),* $(,)?]) => {
        StructDef {
            name: stringify!($ty),
            size: size_of::<$ty>(),
            fields: vec![$(($gt, stringify!($f), offset_of!($ty, $f))),*],
        }
    };
}

pub fn structs() -> Vec<StructDef> {
    use GlslType::*;
    vec![
        def!(
            TlasRecord,
            [
                (Uint, instance_base),
                (Uint, instance_count),
                (Uint, level),
                (Uint, element),
                (Vec3, bounds_min),
                (Uint, box_list_instances),
                (Vec3, bounds_max),
                (Uint, _pad1)
            ]
        ),
        def!(
            InstanceRecord,
            [
                (FloatArray(12), tlas_from_blas),
                (Uint, blas),
                (Uint, flags),
                (Uint, element),
                (Uint, _pad)
            ]
        ),
        def!(
            BlasRecord,
            [
                (Uint, kind),
                (Uint, item_base),
                (Uint, item_count),
                (Uint, level),
                (Vec3, bounds_min),
                (Uint, primitive_count),
                (Vec3, bounds_max),
                (Uint, _pad)
            ]
        ),
        def!(GeometryRecord, [(Uint, mesh), (UintArray(3), _pad)]),
        def!(
            PiRecord,
            [
                (FloatArray(12), child_from_parent),
                (Vec3, aabb_min),
                (Uint, kind),
                (Vec3, aabb_max),
                (Uint, target)
            ]
        ),
        def!(
            LodSelectorRecord,
            [
                (Vec3, center),
                (Float, radius),
                (Uint, level_base),
                (Uint, level_count),
                (Uint, source_mesh),
                (Uint, _pad)
            ]
        ),
        def!(
            LodSlotRecord,
            [
                (Vec3, center_world),
                (Float, radius_world),
                (Uint, selector),
                (Uint, instance),
                (Uint, width),
                (Uint, tlas)
            ]
        ),
        def!(
            MeshRecord,
            [
                (Uint, source_mesh),
                (Uint, lod),
                (Uint, material),
                (Uint, flags),
                (Uint, vertex_count),
                (Uint, triangle_count),
                (Uint, chunk),
                (Uint, element),
                (U64, positions_offset),
                (U64, indices_offset),
                (U64, normals_offset),
                (U64, primitive_map_offset),
                (U64, uvs_offset),
                (U64, _pad_uv),
                (Vec3, bounds_min),
                (Uint, _pad1),
                (Vec3, bounds_max),
                (Uint, _pad2)
            ]
        ),
        def!(
            MaterialRecord,
            [
                (Vec3, base_color),
                (Float, opacity),
                (Vec3, emission),
                (Float, roughness),
                (Float, metallic),
                (Uint, base_color_texture),
                (Uint, alpha_texture),
                (Uint, _pad)
            ]
        ),
        def!(
            LightRecord,
            [
                (Vec3, world_position),
                (Uint, kind),
                (Vec3, world_direction),
                (Float, cos_total),
                (Vec3, radiance),
                (Float, cos_falloff)
            ]
        ),
        def!(
            TextureRecord,
            [
                (Uint, texel_offset),
                (Uint, width),
                (Uint, height),
                (Uint, mip_count)
            ]
        ),
        def!(
            CameraParams,
            [
                (Vec3, world_eye),
                (Uint, width),
                (Vec3, world_dir00),
                (Uint, height),
                (Vec3, world_du),
                (Float, pixels_per_unit_at_1),
                (Vec3, world_dv),
                (Uint, _pad)
            ]
        ),
        def!(
            LodParams,
            [
                (Float, r_max_px),
                (Float, shadow_bias),
                (Uint, stochastic),
                (Int, forced_lod)
            ]
        ),
        def!(
            TlasCompactPush,
            [
                (U64, kept),
                (U64, dst),
                (U64, chunk_first),
                (U64, blas_addresses),
                (Uint, instance_count),
                (UintArray(3), _pad)
            ]
        ),
    ]
}

/// Constants mirrored into GLSL.
pub fn constants() -> Vec<(&'static str, String)> {
    vec![
        ("NONE_U32", format!("{NONE_U32}u")),
        ("BLAS_TRIANGLES", format!("{BLAS_TRIANGLES}u")),
        ("BLAS_AABBS", format!("{BLAS_AABBS}u")),
        ("PI_TLAS", format!("{PI_TLAS}u")),
        ("PI_LOD_SELECTOR", format!("{PI_LOD_SELECTOR}u")),
        ("BOX_LIST_CAPACITY", format!("{BOX_LIST_CAPACITY}u")),
        ("FLAG_NEEDS_ANY_HIT", format!("{FLAG_NEEDS_ANY_HIT}u")),
        ("FLAG_HAS_NORMALS", format!("{FLAG_HAS_NORMALS}u")),
        ("FLAG_HAS_UVS", format!("{FLAG_HAS_UVS}u")),
        ("FLAG_PRIMITIVE_MAP", format!("{FLAG_PRIMITIVE_MAP}u")),
        (
            "PTEX_SECOND_HALF",
            format!("{}u", crate::ptex::PTEX_SECOND_HALF),
        ),
        ("PTEX_QUADS", format!("{}u", crate::ptex::PTEX_QUADS)),
        ("LIGHT_DISTANT", format!("{}u", shade::LIGHT_DISTANT)),
        ("LIGHT_POINT", format!("{}u", shade::LIGHT_POINT)),
        ("LIGHT_SPOT", format!("{}u", shade::LIGHT_SPOT)),
        ("LIGHT_AREA", format!("{}u", shade::LIGHT_AREA)),
        ("MAX_LIGHTS", format!("{}", shade::MAX_LIGHTS)),
        ("ALPHA_CUTOFF", format!("{:?}", shade::ALPHA_CUTOFF)),
        ("RAY_PRIMARY", format!("{}u", lod::RAY_PRIMARY)),
        ("RAY_SHADOW", format!("{}u", lod::RAY_SHADOW)),
        ("LOD_NOT_FORCED", format!("{}", lod::LOD_NOT_FORCED)),
        ("AOV_MISS", format!("{}u", aov::MISS)),
        ("AOV_LOD_FALLBACK", format!("{}u", aov::LOD_FALLBACK)),
        ("AOV_RECORD_BYTES", format!("{}u", size_of::<AovRecord>())),
        // Plain ints: the workgroup size is a layout qualifier.
        ("TLAS_COMPACT_GROUP", format!("{TLAS_COMPACT_GROUP}")),
        (
            "TLAS_COMPACT_PER_THREAD",
            format!("{TLAS_COMPACT_PER_THREAD}"),
        ),
        ("TLAS_COMPACT_CHUNK", format!("{TLAS_COMPACT_CHUNK}")),
    ]
}

/// std430 offsets for a struct's fields, and its size (rounded to its alignment).
pub fn std430_layout(def: &StructDef) -> (Vec<usize>, usize) {
    let mut offset = 0usize;
    let mut max_align = 4usize;
    let mut offsets = Vec::new();
    for (t, _, _) in &def.fields {
        let (size, align) = t.std430();
        offset = offset.div_ceil(align) * align;
        offsets.push(offset);
        offset += size;
        max_align = max_align.max(align);
    }
    (offsets, offset.div_ceil(max_align) * max_align)
}

/// The text of `shaders/generated/abi.glsl`.
pub fn abi_glsl() -> String {
    let mut s = String::from(
        "// GENERATED by motu-abi (crates/motu-abi/src/glsl.rs): do not edit.\n\
         // Regenerate: MOTU_UPDATE_GLSL=1 cargo test -p motu-abi\n\
         #ifndef MOTU_ABI_GLSL\n#define MOTU_ABI_GLSL\n\n",
    );
    for (name, value) in constants() {
        s += &format!("#define {name} {value}\n");
    }
    for def in structs() {
        s += &format!("\n// {} bytes\nstruct {} {{\n", def.size, def.name);
        for (t, name, _) in &def.fields {
            s += &format!("    {}\n", t.decl(name));
        }
        s += "};\n";
    }
    s += "\n#endif\n";
    s
}

#[cfg(test)]
mod tests;
