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
    let _span = tracing::info_span!(
        "pack_sections",
        tlases = view.tlases.len(),
        instances = view.instances.len()
    )
    .entered();
    writer.add_section_slice(SECTION_TLASES, "tlases", view.tlases)?;
    writer.add_section_slice(SECTION_INSTANCES, "instances", view.instances)?;
    writer.add_section_slice(SECTION_BLASES, "blases", view.blases)?;
    writer.add_section_slice(SECTION_GEOMETRIES, "geometries", view.geometries)?;
    writer.add_section_slice(SECTION_PIS, "pis", view.pis)?;
    writer.add_section_slice(SECTION_LOD_SELECTORS, "lod_selectors", view.lod_selectors)?;
    writer.add_section_slice(SECTION_LOD_LEVELS, "lod_levels", view.lod_levels)?;
    writer.add_section_slice(SECTION_MESHES, "meshes", view.meshes)?;
    writer.add_section_slice(SECTION_MATERIALS, "materials", view.materials)?;
    let json = crate::meta::serialise_meta(meta).map_err(|reason| PackError::Schema {
        path: String::new(),
        reason,
    })?;
    writer.add_section(SECTION_META, "meta", 1, &json)?;
    Ok(())
}
