//! Section kinds of a motu scene package. Numbers are part of the format: never reuse one.

use motu_package::SectionKind;

pub const SECTION_META: SectionKind = SectionKind(1);
pub const SECTION_TLASES: SectionKind = SectionKind(2);
pub const SECTION_INSTANCES: SectionKind = SectionKind(3);
pub const SECTION_BLASES: SectionKind = SectionKind(4);
pub const SECTION_GEOMETRIES: SectionKind = SectionKind(5);
pub const SECTION_PIS: SectionKind = SectionKind(6);
pub const SECTION_LOD_SELECTORS: SectionKind = SectionKind(7);
pub const SECTION_LOD_LEVELS: SectionKind = SectionKind(8);
pub const SECTION_MESHES: SectionKind = SectionKind(9);
pub const SECTION_MATERIALS: SectionKind = SectionKind(10);
/// `motu_abi::TextureRecord` per image texture.
pub const SECTION_TEXTURES: SectionKind = SectionKind(11);
/// RGBA8 texels (`u32`) of every texture's mip chain.
pub const SECTION_TEXELS: SectionKind = SectionKind(12);
/// The stream split (`motu_compile::StoredStreamSplit`, written by `motu import` since
/// `stream_split` appeared in the meta): the split hierarchy's TLAS, BLAS and PI tables, its
/// instance map (`u32` per instance: a package instance, or `NONE_U32` for the next extra
/// instance) and its extra instances.
pub const SECTION_SPLIT_TLASES: SectionKind = SectionKind(13);
pub const SECTION_SPLIT_BLASES: SectionKind = SectionKind(14);
pub const SECTION_SPLIT_PIS: SectionKind = SectionKind(15);
pub const SECTION_SPLIT_INSTANCE_SOURCE: SectionKind = SectionKind(16);
pub const SECTION_SPLIT_EXTRA_INSTANCES: SectionKind = SectionKind(17);
/// Boxes inside every triangle BLAS for streamed renders (`motu_compile::proxy_boxes`, written
/// by `motu import` since this kind appeared; optional): a versioned byte blob whose entries
/// each carry a hash of their BLAS's records, so a reader uses only those that match.
pub const SECTION_PROXY_BOXES: SectionKind = SectionKind(18);
/// The proxy clusters of every TLAS of the stream split for streamed renders and the floor
/// (`motu_compile::proxy_clusters`, written by `motu import` since this kind appeared;
/// optional): a versioned byte blob whose per-TLAS entries each carry a hash of the TLAS's
/// record, its instances and the BLAS table, so a reader uses only those that match.
pub const SECTION_PROXY_CLUSTERS: SectionKind = SectionKind(19);
/// Per TLAS of the package's own hierarchy, the BLASes its instances place with their counts
/// (`motu_compile::blas_counts`, written by `motu import` since this kind appeared; optional):
/// what `motu report` walks instead of every instance.
pub const SECTION_BLAS_COUNTS: SectionKind = SectionKind(20);
