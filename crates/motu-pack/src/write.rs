//! Writing the hierarchy tables and the meta section.

use crate::meta::PackageMeta;
use crate::sections::*;
use crate::PackError;
use motu_abi::HierarchyView;
use motu_package::PackageWriter;

/// Adds every table of `view` and the JSON `meta` as sections. Mesh records must already point
/// at their blobs (chunk and offsets).
pub fn write_hierarchy(
    writer: &mut PackageWriter,
    view: &HierarchyView<'_>,
    meta: &PackageMeta,
) -> Result<(), PackError> {
    write_tables(writer, view, meta, true, &mut |_, _| {})
}

/// [`write_hierarchy`] for a caller that already wrote the texels section itself, texture by
/// texture ([`begin_texels`]), so no texel array of the whole scene is ever held: `view.texels`
/// is ignored, `view.textures` must index that section.
pub fn write_hierarchy_after_texels(
    writer: &mut PackageWriter,
    view: &HierarchyView<'_>,
    meta: &PackageMeta,
) -> Result<(), PackError> {
    write_tables(writer, view, meta, false, &mut |_, _| {})
}

/// Instance records written between two `after_piece` calls of
/// [`write_hierarchy_after_texels_then`] (2 MiB).
pub const INSTANCE_PIECE_RECORDS: usize = 1 << 15;

/// [`write_hierarchy_after_texels`] writing the instance table a piece of
/// [`INSTANCE_PIECE_RECORDS`] at a time, calling `after_piece(begin, end)` once records
/// `begin..end` are written: an importer whose table is a mapped file drops the pages read
/// there, so writing the section never makes the whole map resident (issue 48 item 1). The
/// same bytes.
pub fn write_hierarchy_after_texels_then(
    writer: &mut PackageWriter,
    view: &HierarchyView<'_>,
    meta: &PackageMeta,
    after_piece: &mut dyn FnMut(usize, usize),
) -> Result<(), PackError> {
    write_tables(writer, view, meta, false, after_piece)
}

/// Starts the texels section (`u32` RGBA8 texels, every texture's mip chain back to back):
/// write each chain as it is decoded, then finish it and call [`write_hierarchy_after_texels`].
pub fn begin_texels(
    writer: &mut PackageWriter,
) -> Result<motu_package::SectionWriter<'_>, PackError> {
    Ok(writer.begin_section(SECTION_TEXELS, "texels", 4)?)
}

fn write_tables(
    writer: &mut PackageWriter,
    view: &HierarchyView<'_>,
    meta: &PackageMeta,
    with_texels: bool,
    after_instance_piece: &mut dyn FnMut(usize, usize),
) -> Result<(), PackError> {
    let _span = tracing::info_span!(
        "pack_sections",
        tlases = view.tlases.len(),
        instances = view.instances.len()
    )
    .entered();
    writer.add_section_slice(SECTION_TLASES, "tlases", view.tlases)?;
    let element_size = std::mem::size_of::<motu_abi::InstanceRecord>() as u32;
    let mut section = writer.begin_section(SECTION_INSTANCES, "instances", element_size)?;
    for (k, piece) in view.instances.chunks(INSTANCE_PIECE_RECORDS).enumerate() {
        section.write(bytemuck::cast_slice(piece))?;
        let begin = k * INSTANCE_PIECE_RECORDS;
        after_instance_piece(begin, begin + piece.len());
    }
    section.finish()?;
    writer.add_section_slice(SECTION_BLASES, "blases", view.blases)?;
    writer.add_section_slice(SECTION_GEOMETRIES, "geometries", view.geometries)?;
    writer.add_section_slice(SECTION_PIS, "pis", view.pis)?;
    writer.add_section_slice(SECTION_LOD_SELECTORS, "lod_selectors", view.lod_selectors)?;
    writer.add_section_slice(SECTION_LOD_LEVELS, "lod_levels", view.lod_levels)?;
    writer.add_section_slice(SECTION_MESHES, "meshes", view.meshes)?;
    writer.add_section_slice(SECTION_MATERIALS, "materials", view.materials)?;
    writer.add_section_slice(SECTION_TEXTURES, "textures", view.textures)?;
    if with_texels {
        writer.add_section_slice(SECTION_TEXELS, "texels", view.texels)?;
    }
    let json = crate::meta::serialise_meta(meta).map_err(|source| PackError::Meta {
        path: String::new(),
        source,
    })?;
    writer.add_section(SECTION_META, "meta", 1, &json)?;
    Ok(())
}

/// The stored stream split's tables, borrowed (see [`crate::SECTION_SPLIT_TLASES`]).
#[derive(Clone, Copy, Debug)]
pub struct StreamSplitTables<'a> {
    pub tlases: &'a [motu_abi::TlasRecord],
    pub blases: &'a [motu_abi::BlasRecord],
    pub pis: &'a [motu_abi::PiRecord],
    pub instance_source: &'a [u32],
    pub extra_instances: &'a [motu_abi::InstanceRecord],
}

/// Adds the stored stream split's sections (the meta's `stream_split` says what they are).
pub fn write_stream_split(
    writer: &mut PackageWriter,
    t: &StreamSplitTables<'_>,
) -> Result<(), PackError> {
    writer.add_section_slice(SECTION_SPLIT_TLASES, "split_tlases", t.tlases)?;
    writer.add_section_slice(SECTION_SPLIT_BLASES, "split_blases", t.blases)?;
    writer.add_section_slice(SECTION_SPLIT_PIS, "split_pis", t.pis)?;
    writer.add_section_slice(
        SECTION_SPLIT_INSTANCE_SOURCE,
        "split_instance_source",
        t.instance_source,
    )?;
    writer.add_section_slice(
        SECTION_SPLIT_EXTRA_INSTANCES,
        "split_extra_instances",
        t.extra_instances,
    )?;
    Ok(())
}

#[cfg(test)]
mod tests;
