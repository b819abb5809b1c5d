//! The package's last steps: the meta, textures, stream split, proxy boxes and clusters written
//! after compiling, the import's summary, and the per-element counts.

use super::{ImportOptions, ImportSummary};
use crate::precut::ClusterBoxes;
use crate::ImportError;
use motu_compile::CompiledScene;
use motu_ingest::IngestReport;
use motu_pack::{ElementMeta, PackageMeta};
use motu_package::{PackageWriter, WriteSummary};
use motu_scene::{ElementId, PrototypeId, Scene};
use std::collections::HashMap;
use std::path::Path;
use std::time::Instant;

/// The scene's counts a package's meta records, taken before compiling (they read every edge;
/// file-held edges then leave the resident set before the compiler's instance table grows).
pub(super) struct SceneCounts {
    pub stats: motu_scene::SceneStats,
    pub elements: Vec<ElementMeta>,
}

impl SceneCounts {
    pub fn of(scene: &Scene) -> Self {
        let counts = Self {
            stats: scene.stats(),
            elements: element_stats(scene),
        };
        if let Err(error) = scene.release_edge_pages() {
            tracing::debug!(%error, "could not release the edge map's pages");
        }
        counts
    }
}

pub(super) fn summary(
    (s, split_ms, proxy_boxes_ms, proxy_clusters_ms): (WriteSummary, f64, f64, f64),
    st: &motu_scene::SceneStats,
    compiled: &CompiledScene,
    report: &IngestReport,
    parse_ms: f64,
    compile_ms: f64,
    pack_start: Instant,
) -> ImportSummary {
    ImportSummary {
        package: s.path.display().to_string(),
        file_bytes: s.file_bytes,
        chunks: s.chunk_count,
        parse_ms,
        cut_ms: 0.0,
        cut_wait_ms: 0.0,
        cut_triangles: 0,
        compile_ms,
        pack_ms: pack_start.elapsed().as_secs_f64() * 1e3,
        compile_phases: (&compiled.report.phases).into(),
        stream_split_ms: split_ms,
        proxy_boxes_ms,
        proxy_clusters_ms,
        meshes: st.meshes,
        instances: st.instances,
        flattened_instances: st.flattened_instances,
        tlas_count: compiled.report.tlas_count,
        blas_count: compiled.report.blas_count,
        warnings: report.warnings.len(),
        curves_not_converted: report.curves - report.curve_ribbons,
        curve_ribbons: report.curve_ribbons,
        curve_ribbon_triangles: report.curve_ribbon_triangles,
        unsupported_shapes: report.unsupported_shapes,
        skipped_shapes: report.skipped_shapes,
        peak_rss_bytes: crate::peak_rss_bytes().unwrap_or(0),
    }
}

/// Writes the package's sections and finishes it. Takes the scene: it is dropped once the
/// meta and textures are made, before the stream split (the import's peak: the scene's edges
/// need not be held beside it).
// The import's state at its end, each piece from a different step: no struct holds them.
#[allow(clippy::too_many_arguments)]
pub(super) fn finish(
    mut writer: PackageWriter,
    scene: Scene,
    counts: &SceneCounts,
    compiled: &mut CompiledScene,
    report: &IngestReport,
    source: &Path,
    o: &ImportOptions,
    cut_boxes: &HashMap<u32, ClusterBoxes>,
    scratch_dir: &Path,
) -> Result<(WriteSummary, f64, f64, f64), ImportError> {
    let owned = scene;
    let scene = &owned;
    // A subset package describes only what it holds.
    let mut elements = counts.elements.clone();
    let mut scene_stats = counts.stats.clone();
    if !o.subset.is_empty() {
        elements.retain(|e| o.subset.contains(&e.name));
        scene_stats.instances = elements.iter().map(|e| e.instances).sum();
        scene_stats.flattened_instances = compiled.report.flattened_instances;
        scene_stats.unique_triangles = elements.iter().map(|e| e.unique_triangles).sum();
        scene_stats.instanced_triangles = elements.iter().map(|e| e.instanced_triangles).sum();
        scene_stats.meshes = elements.iter().map(|e| e.meshes).sum();
    }
    let meta = PackageMeta {
        schema: motu_pack::SCHEMA.into(),
        source: source.display().to_string(),
        levels: o.levels_text.clone(),
        max_instances_per_tlas: o.max_instances,
        lod_levels: o.lod_levels.unwrap_or(1),
        root_tlas: compiled.root_tlas,
        cameras: scene.cameras().to_vec(),
        lights: scene.lights().to_vec(),
        material_names: scene.materials().iter().map(|m| m.name.clone()).collect(),
        material_ptex: scene
            .materials()
            .iter()
            .map(|m| m.ptex.as_ref().map(|p| p.display().to_string()))
            .collect(),
        mesh_names: scene.meshes().iter().map(|m| m.name.clone()).collect(),
        elements: elements.clone(),
        scene: scene_stats,
        compile: serde_json::to_value(crate::compile_report::CompileReport::from(
            &compiled.report,
        ))?,
        warnings: report.warnings.clone(),
        curves: motu_pack::CurveMeta {
            curves: report.curves,
            ribbons: report.curve_ribbons,
            ribbon_triangles: report.curve_ribbon_triangles,
        },
        stream_split: None,
    };
    let mut meta = meta;
    let caps = crate::textures::Caps {
        image_max: o.texture_max,
        ptex_max: o.ptex_max,
    };
    let textures = crate::textures::write_textures(&mut writer, scene, caps, &mut meta.warnings)?;
    crate::memory::log_phase("textures");
    drop(owned);
    crate::memory::release_free_heap();
    crate::memory::log_phase("scene dropped");
    let t = Instant::now();
    let crate::split::StreamSplitWritten {
        meta: split_meta,
        split,
        table,
    } = crate::split::write_stream_split(
        &mut writer,
        compiled,
        o.stream_split_instances,
        scratch_dir,
    )?;
    meta.stream_split = Some(split_meta);
    let split_ms = t.elapsed().as_secs_f64() * 1e3;
    crate::memory::log_phase("stream split");
    let t = Instant::now();
    // The hierarchy a streamed render draws (the split's pieces in place of a large root):
    // the boxes and clusters are made over it, so their records and hashes are the reader's.
    // The split holds the instance table meanwhile (no copy of it).
    let base = motu_abi::HierarchyView {
        textures: &textures,
        texels: &[],
        instances: table
            .as_ref()
            .map_or(&compiled.instances[..], |m| m.records()),
        ..compiled.view()
    };
    let streamed = split.as_ref().map_or(base, |(_, s)| s.view(&base));
    if o.proxy_boxes {
        crate::proxy_boxes::write_proxy_boxes(
            &mut writer,
            &streamed,
            cut_boxes,
            o.proxy_readback_bytes,
            o.chunk_bytes,
        )?;
    }
    let proxy_boxes_ms = t.elapsed().as_secs_f64() * 1e3;
    crate::memory::log_phase("proxy boxes");
    let t = Instant::now();
    if o.proxy_clusters {
        let release = || release_tables(split.as_ref().map(|(_, s)| s), table.as_ref());
        crate::split::write_proxy_clusters(&mut writer, &streamed, &release)?;
    }
    let proxy_clusters_ms = t.elapsed().as_secs_f64() * 1e3;
    let t = Instant::now();
    // The package's table is in its own file: the split (its map, file and tables) goes.
    let split = if table.is_some() { None } else { split };
    // The clusters' tables and batches are freed: their pages go back to the system before
    // the instance table comes back to the heap (a parked split's gather, where the package's
    // table was not parked itself), not beside it.
    crate::memory::release_free_heap();
    if let Some((stored, split)) = split {
        split
            .give_back(compiled, &stored)
            .map_err(ImportError::Compile)?;
    }
    let split_ms = split_ms + t.elapsed().as_secs_f64() * 1e3;
    crate::memory::log_phase("proxy clusters");
    let mut view = compiled.view();
    view.textures = &textures;
    view.texels = &[];
    if let Some(m) = &table {
        view.instances = m.records();
    }
    // A mapped table is read a piece at a time, its pages dropped behind.
    let release = || release_tables(None, table.as_ref());
    // What `motu report` walks instead of every instance (the package's own tables).
    crate::split::write_blas_counts(&mut writer, &view, &release)?;
    crate::memory::log_phase("blas counts");
    motu_pack::write_hierarchy_after_texels_then(&mut writer, &view, &meta, &mut |begin, end| {
        if let Some(m) = &table {
            let _ = m.release_range(begin, end);
        }
    })?;
    drop(table);
    crate::memory::log_phase("hierarchy");
    let written = writer.finish().map_err(ImportError::FinishPackage)?;
    crate::memory::log_phase("finish");
    Ok((written, split_ms, proxy_boxes_ms, proxy_clusters_ms))
}

/// Drops the pages of the mapped instance tables, the split's (`split`) and the package's
/// (`table`), read so far from the resident set (a failed hint costs only memory).
fn release_tables(
    split: Option<&motu_compile::StreamSplit>,
    table: Option<&motu_compile::InstanceMap>,
) {
    if let Some(s) = split {
        s.release_instance_pages();
    }
    if let Some(m) = table {
        let _ = m.release_pages();
    }
}

/// Per-element counts: each element's root edges and root meshes, and everything they reach.
pub fn element_stats(scene: &Scene) -> Vec<ElementMeta> {
    let n_proto = scene.prototypes().len();
    let root = scene.root();
    let root_meshes = scene.meshes_of(root);
    let tris = |p: PrototypeId| -> u64 {
        scene
            .meshes_of(p)
            .iter()
            .map(|&m| scene.mesh(m).triangle_count as u64)
            .sum()
    };
    let blob = |m: motu_scene::MeshId| -> u64 {
        let i = scene.mesh(m);
        motu_pack::MeshBlobLayout::new(
            i.vertex_count as u64,
            i.triangle_count as u64,
            i.has_normals,
        )
        .with_uvs(i.has_uvs)
        .len
    };
    scene
        .elements()
        .iter()
        .enumerate()
        .map(|(ei, e)| {
            let ei = ElementId(ei as u32);
            let mut paths = vec![0u64; n_proto];
            for (edge, &el) in scene.walk_edges(root).zip(scene.root_edge_elements()) {
                if el == ei {
                    paths[edge.child.index()] = paths[edge.child.index()].saturating_add(1);
                }
            }
            // Parents before children: the reverse of the topological order.
            for &p in scene.topo_order().iter().rev() {
                if p == root || paths[p.index()] == 0 {
                    continue;
                }
                let n = paths[p.index()];
                for edge in scene.walk_edges(p) {
                    paths[edge.child.index()] = paths[edge.child.index()].saturating_add(n);
                }
            }
            let mut m = ElementMeta {
                id: ei.0,
                name: e.name.clone(),
                ..Default::default()
            };
            m.instances = scene
                .root_edge_elements()
                .iter()
                .filter(|&&x| x == ei)
                .count() as u64;
            for (mid, &el) in root_meshes.iter().zip(scene.root_mesh_elements()) {
                if el == ei {
                    let t = scene.mesh(*mid).triangle_count as u64;
                    m.unique_triangles += t;
                    m.instanced_triangles += t;
                    m.meshes += 1;
                    m.mesh_bytes += blob(*mid);
                }
            }
            for p in scene.prototype_ids() {
                if p == root || paths[p.index()] == 0 {
                    continue;
                }
                let t = tris(p);
                m.instances += scene.edges(p).len() as u64;
                m.unique_triangles += t;
                m.instanced_triangles = m
                    .instanced_triangles
                    .saturating_add(paths[p.index()].saturating_mul(t));
                if t > 0 {
                    m.flattened_instances = m.flattened_instances.saturating_add(paths[p.index()]);
                }
                for &mid in scene.meshes_of(p) {
                    m.meshes += 1;
                    m.mesh_bytes += blob(mid);
                }
            }
            m
        })
        .collect()
}
