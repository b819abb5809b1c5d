//! The import pipeline: parse → scene (geometry streamed into the package) → compile → pack.
//! Nothing here holds more than the instance skeleton in memory: mesh data goes to chunks as it
//! is parsed and LOD meshes go to chunks as they are made.

use crate::precut::{PrecutGeometry, CLUSTER_GROUP};
use crate::ImportError;
use motu_abi::MeshRecord;
use motu_compile::{CompileOptions, CompiledScene, Levels};
use motu_ingest::{IngestOptions, IngestReport};
use motu_pack::{place_mesh_record, PackError, PackageGeometry};
use motu_package::{PackageWriter, WriterOptions};
use motu_scene::{ElementId, MeshLocation, Scene, StoreError};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Chunk group for LOD meshes the compiler makes (kept apart from element groups).
const LOD_GROUP: u32 = u32::MAX - 1;

mod finish;
pub use finish::element_stats;
use finish::{finish, summary, SceneCounts};

pub struct ImportOptions {
    pub levels: Levels,
    pub levels_text: String,
    pub max_instances: u32,
    pub max_tlas_scratch_bytes: Option<u64>,
    /// The partitioner's bound (`--max-blas-triangles`); `None` picks it from the scene's size
    /// ([`motu_compile::auto_max_blas_triangles`]: 2^16, less on small scenes).
    pub max_blas_triangles: Option<u32>,
    pub lod_levels: Option<u32>,
    pub lod_min_triangles: u32,
    pub zstd_level: Option<i32>,
    pub allow_missing: bool,
    pub pbrt_version: Option<u32>,
    pub subset: Vec<String>,
    pub chunk_bytes: u64,
    pub parallel: bool,
    pub curve_ribbons: bool,
    /// Largest side of an image texture's finest mip level (`--texture-max`).
    pub texture_max: u32,
    /// Most texels a Ptex face keeps per edge (`--ptex-max`; larger faces are halved).
    pub ptex_max: u32,
    /// Store the boxes inside every triangle BLAS (the `proxy_boxes` section, FORMAT.md) so
    /// streamed renders need not read every mesh at start (`--no-proxy-boxes`: off).
    pub proxy_boxes: bool,
    /// Store the proxy clusters of every TLAS of the stream split (the `proxy_clusters`
    /// section, FORMAT.md) so streamed starts and `motu report` need not run a binned SAH over
    /// every instance (`--no-proxy-clusters`: off).
    pub proxy_clusters: bool,
    /// `--stream-split-instances`: the cap the stored stream split (and the proxy boxes and
    /// clusters made over the hierarchy it gives) is made for, recorded in the meta
    /// (`stream_split.cap_instances`), so streamed renders split at it by default
    /// ([`motu_compile::STREAM_SPLIT_INSTANCES`] by default; 0: no split).
    pub stream_split_instances: u32,
    /// Called as parsing advances and once when it is done (the CLI's progress bar).
    pub progress: Option<ProgressFn>,
    /// Cut meshes over the partition bound into clusters while parsing (`precut.rs`) rather
    /// than when compiling; the same records either way. On by default; off for A/B tests.
    pub cut_while_parsing: bool,
    /// Source-mesh bytes the cutting thread may lag behind the parser by (the memory that
    /// overlapping cutting with parsing costs); 0 cuts each mesh before the parser goes on.
    pub cut_queue_bytes: u64,
    /// Chunk bytes `write_proxy_boxes` reads back at once for BLASes not cut while parsing
    /// (at least two chunks, at most one per pool thread up to 16): with 64 MiB chunks a
    /// 16-thread pool read 1 GiB at once before this bound (issue 48 item 1).
    pub proxy_readback_bytes: u64,
}

/// `motu import`'s defaults (`shared/CLI.md`): `--levels ml`, the device's 2^24 − 1 instances
/// per TLAS, triangles per BLAS chosen from the scene (2^16 on big scenes), no LOD, 64 MiB chunks, raw (no zstd), parallel parsing,
/// curves as ribbons, textures up to 1024², no progress reports.
impl Default for ImportOptions {
    fn default() -> Self {
        Self {
            levels: Levels::Ml,
            levels_text: "ml".into(),
            max_instances: (1 << 24) - 1,
            max_tlas_scratch_bytes: None,
            max_blas_triangles: None,
            lod_levels: None,
            lod_min_triangles: 10_000,
            zstd_level: None,
            allow_missing: false,
            pbrt_version: None,
            subset: Vec::new(),
            chunk_bytes: 64 << 20,
            parallel: true,
            curve_ribbons: true,
            texture_max: 1024,
            ptex_max: crate::textures::DEFAULT_PTEX_MAX,
            proxy_boxes: true,
            stream_split_instances: motu_compile::STREAM_SPLIT_INSTANCES,
            proxy_clusters: true,
            progress: None,
            cut_while_parsing: true,
            cut_queue_bytes: crate::precut::DEFAULT_CUT_QUEUE_BYTES,
            proxy_readback_bytes: crate::proxy_boxes::DEFAULT_PROXY_READBACK_BYTES,
        }
    }
}

/// Progress of an import, for a progress bar.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImportProgress {
    /// Scene bytes parsed so far, out of an estimate (the scene text beside the entry file;
    /// files there that the scene never includes count too, and PLY data is not in it).
    Parsing { bytes: u64, total_bytes: u64 },
    /// Parsing is done; compiling and packing follow.
    Parsed,
}

/// Receives [`ImportProgress`] reports (from the parser's threads).
pub type ProgressFn = std::sync::Arc<dyn Fn(ImportProgress) + Send + Sync>;

#[derive(Debug, serde::Serialize)]
pub struct ImportSummary {
    pub package: String,
    pub file_bytes: u64,
    pub chunks: u32,
    pub parse_ms: f64,
    /// Of `parse_ms`: meshes over the partition bound cut into clusters while parsing.
    pub cut_ms: f64,
    /// Of `parse_ms`: the time the parser waited for the cutting thread (the rest of
    /// `cut_ms` overlapped parsing).
    pub cut_wait_ms: f64,
    /// Triangles of the meshes cut while parsing.
    pub cut_triangles: u64,
    pub compile_ms: f64,
    pub pack_ms: f64,
    /// Where `compile_ms` went (the compiler's phases: analyze, emit with its source-mesh
    /// loads, partitioning and stores, finalize).
    pub compile_phases: crate::compile_report::CompilePhases,
    /// Of `pack_ms`: the stream split made and stored for readers (FORMAT.md).
    pub stream_split_ms: f64,
    /// Of `pack_ms`: the boxes inside triangle BLASes made and stored for streamed renders
    /// (0 with `--no-proxy-boxes`).
    pub proxy_boxes_ms: f64,
    /// Of `pack_ms`: the proxy clusters of the split hierarchy's TLASes made and stored for
    /// streamed renders and the report's floor (0 with `--no-proxy-clusters`).
    pub proxy_clusters_ms: f64,
    pub meshes: u64,
    pub instances: u64,
    pub flattened_instances: u64,
    pub tlas_count: u64,
    pub blas_count: u64,
    pub warnings: usize,
    pub curves_not_converted: u64,
    pub curve_ribbons: u64,
    /// Triangles of the curves tessellated as ribbons.
    pub curve_ribbon_triangles: u64,
    pub unsupported_shapes: u64,
    pub skipped_shapes: u64,
    /// Peak resident memory of the importing process (Linux `VmHWM`), 0 if unknown.
    pub peak_rss_bytes: u64,
}

fn writer_options(o: &ImportOptions) -> WriterOptions {
    WriterOptions {
        target_chunk_bytes: o.chunk_bytes,
        zstd_level: o.zstd_level,
        // The package is written once and read back little during the import: past the page
        // cache its writes cost little system time (`motu-package`'s `sink.rs`).
        direct_io: true,
    }
}

/// Resolves element names; unknown names are an error listing the valid ones.
pub fn resolve_subset(names: &[String], known: &[String]) -> Result<Vec<u32>, ImportError> {
    if names.iter().any(|n| n.trim().is_empty()) {
        return Err(ImportError::EmptySubsetName {
            known: known.to_vec(),
        });
    }
    let mut ids = Vec::new();
    let mut unknown = Vec::new();
    for n in names {
        match known.iter().position(|k| k == n) {
            Some(i) => ids.push(i as u32),
            None => unknown.push(n.clone()),
        }
    }
    if !unknown.is_empty() {
        return Err(ImportError::UnknownElements {
            unknown,
            known: known.to_vec(),
        });
    }
    Ok(ids)
}

/// Meshes of more triangles than this go to the spill file in a direct import: the bound
/// given, or the least bound the automatic choice can make.
fn bound_spilled(o: &ImportOptions) -> u32 {
    o.max_blas_triangles
        .unwrap_or(motu_compile::MIN_AUTO_MAX_BLAS_TRIANGLES)
        .min(motu_compile::DEFAULT_MAX_PER_NODE)
}

pub fn import(
    scene_path: &Path,
    out: &Path,
    o: &ImportOptions,
) -> Result<ImportSummary, ImportError> {
    let path = scene_path.to_path_buf();
    match std::fs::metadata(scene_path) {
        Ok(m) if m.is_file() => {}
        // Moana's JSON+OBJ base package may be named by its folder.
        Ok(m) if m.is_dir() && motu_ingest::is_moana_json(scene_path) => {}
        Ok(m) => {
            return Err(ImportError::NotASceneFile {
                path,
                kind: motu_package::identity::describe_file_type(&m.file_type()),
            })
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(ImportError::SceneMissing { path })
        }
        Err(error) => return Err(ImportError::SceneUnreadable { path, error }),
    }
    // With --subset, geometry is first streamed into a scratch package beside the output, and
    // only what the subset references is copied into the real one.
    let direct = o.subset.is_empty();
    let first_target: PathBuf = if direct {
        out.to_path_buf()
    } else {
        out.with_extension("subset-scratch.motu")
    };
    let t0 = Instant::now();
    let (geometry, precut) = create_geometry(out, &first_target, direct, o)?;
    let store: Box<dyn motu_scene::GeometryStore> = match &precut {
        Some(p) => Box::new(p.clone()),
        None => Box::new(geometry.clone()),
    };
    // The bar's total: the scene text beside the entry file (an estimate: files there that the
    // scene never includes count too, and PLY data is not in it).
    let total = scene_text_bytes(scene_path.parent().unwrap_or(Path::new(".")));
    // The instance edges' scratch files go beside the package (unnamed: nothing is left
    // behind): written as they are parsed, they never sit in memory whole (issue 48 item 1).
    let dir = match out.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    // Called at each file the parser enters: reports progress and, every
    // `TRIM_EVERY_BYTES` of scene text, hands the heap's free pages back (the parse's peak
    // is mostly freed but resident heap, growing with the scene: issue 48 item 1).
    let report = o.progress.clone();
    let trim = crate::memory::TrimEvery::new(crate::memory::TRIM_EVERY_BYTES);
    let ingest_opts = IngestOptions {
        progress: Some(motu_ingest::ProgressFn(std::sync::Arc::new(
            move |bytes, _files| {
                trim.at(bytes);
                if let Some(report) = &report {
                    report(ImportProgress::Parsing {
                        bytes,
                        total_bytes: total.max(bytes),
                    });
                }
            },
        ))),
        allow_missing: o.allow_missing,
        pbrt_version: o.pbrt_version,
        parallel: o.parallel,
        curve_ribbons: o.curve_ribbons,
        edge_spill_dir: Some(dir.to_path_buf()),
    };
    let (mut scene, mut report) = motu_ingest::ingest_file(scene_path, &ingest_opts, store)
        .map_err(|source| ImportError::Ingest { path, source })?;
    if let Some(p) = &precut {
        p.finish().map_err(|source| ImportError::Cut { source })?;
    }
    if let Some(report) = &o.progress {
        report(ImportProgress::Parsed);
    }
    // Inputs known only now (PLY, included files): the package must not replace one.
    check_not_an_input("-o", out, report.input_files.iter().map(PathBuf::as_path))?;
    warn_on_count_overflow(&scene, &mut report);
    let parse_ms = t0.elapsed().as_secs_f64() * 1e3;
    tracing::info!(parse_ms, peak_rss_bytes = crate::peak_rss_bytes(), "parsed");
    crate::memory::log_phase("parse");
    // What the parser's threads freed goes back before the compiler's tables grow.
    crate::memory::release_free_heap();
    crate::memory::log_phase("heap trimmed");
    // Edges too few to fill a chunk were kept on the heap: they go to the file now.
    scene
        .move_edges_to_file(dir)
        .map_err(|source| ImportError::EdgeFile {
            dir: dir.to_path_buf(),
            source,
        })?;
    let counts = SceneCounts::of(&scene);
    crate::memory::log_phase("edges to file");

    let element_names: Vec<String> = scene.elements().iter().map(|e| e.name.clone()).collect();
    let subset_ids = resolve_subset(&o.subset, &element_names)?;
    let max_blas_triangles = o.max_blas_triangles.unwrap_or_else(|| {
        let bound = motu_compile::auto_max_blas_triangles(&scene);
        tracing::info!(bound, "partition bound chosen from the scene's size");
        bound
    });
    let copts = CompileOptions {
        levels: o.levels,
        max_instances_per_tlas: o.max_instances,
        max_tlas_scratch_bytes: o.max_tlas_scratch_bytes.unwrap_or(u64::MAX),
        max_blas_triangles,
        lod_levels: o.lod_levels,
        lod_triangle_threshold: o.lod_min_triangles,
        subset: (!direct).then(|| subset_ids.iter().map(|&i| ElementId(i)).collect()),
        // A root over the device's cap (island 0.63 and up) is split by key, its records in a
        // scratch file beside the package meanwhile (issue 48 item 1: the compile's peak).
        split_scratch_dir: Some(dir.to_path_buf()),
        ..Default::default()
    };

    if direct {
        let load = |m| scene.mesh_data(m).map_err(StoreError::from);
        let mut copied: HashMap<u32, MeshLocation> = HashMap::new();
        let (mut compiled, compile_ms) =
            compile_into(&scene, &copts, &geometry, &load, precut.as_ref(), |m| {
                let id = motu_scene::MeshId(m.source_mesh);
                let at = scene.mesh(id).location;
                if !PackageGeometry::is_spilled(at) {
                    return Ok(at);
                }
                // Spilled under the automatic bound's least value, but within the bound chosen:
                // kept whole, so its data moves from the spill file into the package (once).
                if max_blas_triangles <= bound_spilled(o) {
                    return Err(ImportError::Internal(format!(
                        "mesh {} over the BLAS bound was compiled whole",
                        m.source_mesh
                    )));
                }
                if let Some(&c) = copied.get(&m.source_mesh) {
                    return Ok(c);
                }
                let data = scene
                    .mesh_data(id)
                    .map_err(|source| ImportError::MeshData {
                        mesh: m.source_mesh,
                        source,
                    })?;
                let c = geometry.append_mesh(m.element, &data)?;
                copied.insert(m.source_mesh, c);
                Ok(c)
            })?;
        let t2 = Instant::now();
        let writer = geometry.take_writer()?;
        let cut_boxes = precut.as_ref().map(PrecutGeometry::take_record_boxes);
        let s = finish(
            writer,
            scene,
            &counts,
            &mut compiled,
            &report,
            scene_path,
            o,
            &cut_boxes.unwrap_or_default(),
            dir,
        )?;
        let mut sum = summary(
            s,
            &counts.stats,
            &compiled,
            &report,
            parse_ms,
            compile_ms,
            t2,
        );
        (sum.cut_ms, sum.cut_wait_ms, sum.cut_triangles) =
            precut.as_ref().map_or((0.0, 0.0, 0), |p| p.cut_report());
        return Ok(sum);
    }
    // Finish the scratch package so its chunks can be read back, then copy only the blobs the
    // subset references into the real package.
    let scratch_writer = geometry.take_writer()?;
    scratch_writer
        .finish()
        .map_err(ImportError::FinishScratch)?;
    let result = (|| {
        let scratch = motu_package::Package::open(&first_target)?;
        let final_geo =
            PackageGeometry::new(PackageWriter::create(out, writer_options(o)).map_err(
                |source| ImportError::CreatePackage {
                    path: out.to_path_buf(),
                    source,
                },
            )?);
        let mut copied: HashMap<u32, MeshLocation> = HashMap::new();
        // The scene's store wrote the scratch package, now finished: LOD chains and the
        // partitioner read source meshes back from it.
        let read_source = |m: motu_scene::MeshId| {
            let info = scene.mesh(m);
            motu_pack::read_mesh_blob(
                &scratch,
                info.location,
                info.vertex_count,
                info.triangle_count,
                info.has_normals,
                info.has_uvs,
            )
        };
        let load = |m: motu_scene::MeshId| read_source(m).map_err(StoreError::from);
        let (mut compiled, compile_ms) =
            compile_into(&scene, &copts, &final_geo, &load, None, |m| {
                if let Some(&at) = copied.get(&m.source_mesh) {
                    return Ok(at);
                }
                let data = read_source(motu_scene::MeshId(m.source_mesh))?;
                let at = final_geo.append_mesh(m.element, &data)?;
                copied.insert(m.source_mesh, at);
                Ok(at)
            })?;
        let t2 = Instant::now();
        let writer = final_geo.take_writer()?;
        let s = finish(
            writer,
            scene,
            &counts,
            &mut compiled,
            &report,
            scene_path,
            o,
            &HashMap::new(),
            dir,
        )?;
        Ok(summary(
            s,
            &counts.stats,
            &compiled,
            &report,
            parse_ms,
            compile_ms,
            t2,
        ))
    })();
    let _ = std::fs::remove_file(&first_target);
    result
}

/// The store the parser writes meshes through: the package writer (at `first_target`), a
/// spill file in a direct import, and the cutting store over them where it applies.
fn create_geometry(
    out: &Path,
    first_target: &Path,
    direct: bool,
    o: &ImportOptions,
) -> Result<(PackageGeometry, Option<PrecutGeometry>), ImportError> {
    let writer = PackageWriter::create(first_target, writer_options(o)).map_err(|source| {
        ImportError::CreatePackage {
            path: first_target.to_path_buf(),
            source,
        }
    })?;
    // Meshes over the partitioner's bound are only ever stored as clusters: in a direct import
    // their whole data goes to a spill file that is dropped after compiling, not the package.
    // The automatic bound is known only once the scene is parsed, so meshes over its least
    // value spill; those it then keeps whole are copied into the package by the compile sink.
    // Once the bound is known, meshes over it are cut as they are stored instead (`precut`).
    let geometry = if direct {
        let spill_path = out.with_extension("partition-spill.motu");
        // The spill is read back whole while compiling: through the page cache, where a
        // direct write's pages would have to come back from the disk (kernel `_copy_to_iter`
        // 0.2% → 5.3% of an import's CPU samples when the spill was written direct too).
        let spill_options = WriterOptions {
            direct_io: false,
            ..writer_options(o)
        };
        let spill = PackageWriter::create(&spill_path, spill_options).map_err(|source| {
            ImportError::CreateScratch {
                path: out.to_path_buf(),
                source,
            }
        })?;
        let geometry = PackageGeometry::new(writer).with_spill(spill, u64::from(bound_spilled(o)));
        if o.max_blas_triangles.is_none() {
            // Past this many triangles the automatic bound is known: larger scenes send only
            // the meshes over it through the spill file, not every mesh over its least value.
            let settled =
                motu_compile::DEFAULT_MAX_BLAS_TRIANGLES.min(motu_compile::DEFAULT_MAX_PER_NODE);
            geometry.raise_spill_bound_after(
                motu_compile::auto_bound_settles_at_triangles(),
                u64::from(settled),
            )
        } else {
            geometry
        }
    } else {
        PackageGeometry::new(writer)
    };
    let precut = precut_store(&geometry, direct, o);
    Ok((geometry, precut))
}

/// The store that cuts meshes over the partition bound while parsing (`precut.rs`), where it
/// applies: a direct import (no scratch package) without LOD or `--levels auto`.
fn precut_store(
    geometry: &PackageGeometry,
    direct: bool,
    o: &ImportOptions,
) -> Option<PrecutGeometry> {
    let lod = o.lod_levels.is_some_and(|l| l >= 2);
    if !o.cut_while_parsing || !direct || lod || o.levels == motu_compile::Levels::Auto {
        return None;
    }
    let cap = motu_compile::DEFAULT_MAX_PER_NODE;
    let store = match o.max_blas_triangles {
        Some(0) => return None,
        Some(b) => PrecutGeometry::new(
            geometry.clone(),
            Some(b.min(cap).max(1)),
            None,
            o.cut_queue_bytes,
        ),
        None => {
            let settles = (
                motu_compile::auto_bound_settles_at_triangles(),
                motu_compile::DEFAULT_MAX_BLAS_TRIANGLES.min(cap),
            );
            // Tests settle small scenes early, at the bound they are known to get.
            #[cfg(test)]
            let settles = crate::precut::tests::SETTLES
                .with(std::cell::Cell::get)
                .unwrap_or(settles);
            PrecutGeometry::new(geometry.clone(), None, Some(settles), o.cut_queue_bytes)
        }
    };
    // The clusters' proxy boxes made as they are cut, from memory (`proxy_boxes.rs`).
    Some(if o.proxy_boxes {
        store.with_boxes()
    } else {
        store
    })
}

/// Flattened counts that saturate 2^64 mean exponentially deep instancing (each level
/// instancing the one below several times): importable, but every flattened figure is a lower
/// bound and a full traversal cannot finish; renders bound each ray's work and fail on truncated
/// rays unless allowed.
fn warn_on_count_overflow(scene: &Scene, report: &mut IngestReport) {
    let st = scene.stats();
    let mut over = Vec::new();
    if st.flattened_instances == u64::MAX {
        over.push("flattened instances");
    }
    if st.instanced_triangles == u64::MAX {
        over.push("instanced triangles");
    }
    if over.is_empty() {
        return;
    }
    let msg = format!(
        "{} overflow 2^64 (exponentially deep instancing: {} levels, {} prototypes, {} instance edges); the counts shown are saturated, and renders cut each ray short after --max-traces-per-ray walks (an error unless --allow-truncated)",
        over.join(" and "),
        st.max_depth,
        st.prototypes,
        st.instances
    );
    tracing::warn!("{msg}");
    report.warnings.push(msg);
}

/// Compiles `scene` (source meshes read by `load`, one at a time, for LOD chains and the
/// partitioner), appending the meshes the compiler makes (LOD levels, clusters) to `geo` as
/// they come, and points every mesh record at its blob: whole source meshes where
/// `source_location` says, made meshes where they were appended. Returns the compiled scene
/// and the compile time.
///
/// The made meshes are stored by a writer thread (a few in flight, in the order made, so the
/// package is the same) while the compiler goes on partitioning: storing is copying and
/// writing chunks, partitioning is arithmetic, and the two overlap.
fn compile_into(
    scene: &Scene,
    copts: &CompileOptions,
    geo: &PackageGeometry,
    load: &motu_compile::MeshLoader<'_>,
    precut: Option<&PrecutGeometry>,
    mut source_location: impl FnMut(&MeshRecord) -> Result<MeshLocation, ImportError>,
) -> Result<(CompiledScene, f64), ImportError> {
    let t = Instant::now();
    type Made = (u32, motu_scene::MeshData, Option<Vec<u32>>);
    let (tx, rx) = std::sync::mpsc::sync_channel::<Made>(MADE_IN_FLIGHT);
    let (compiled, made_locations) = std::thread::scope(|scope| {
        let writer = scope.spawn(move || -> Result<HashMap<u32, MeshLocation>, PackError> {
            let mut made: HashMap<u32, MeshLocation> = HashMap::new();
            for (rec, data, map) in rx {
                let group = if map.is_some() {
                    CLUSTER_GROUP
                } else {
                    LOD_GROUP
                };
                made.insert(rec, geo.append_mesh_mapped(group, &data, map.as_deref())?);
            }
            Ok(made)
        });
        let mut sink = |rec: u32,
                        data: &motu_scene::MeshData,
                        map: Option<&[u32]>|
         -> Result<(), StoreError> {
            tx.send((rec, data.clone(), map.map(<[u32]>::to_vec)))
                .map_err(|_| "the mesh writer stopped".into())
        };
        let mut cut_locations: HashMap<u32, MeshLocation> = HashMap::new();
        let mut stored = |m: motu_scene::MeshId, bound: u32, first: u32| {
            precut.and_then(|p| p.clusters(m, bound, first, &mut cut_locations))
        };
        let compiled =
            motu_compile::compile_with_sources(scene, copts, load, &mut stored, &mut sink);
        drop(tx);
        let made = writer
            .join()
            .map_err(|_| ImportError::Internal("the mesh writer panicked".into()))?;
        // The writer's error first: the compiler then only saw a closed queue.
        let mut made = made?;
        made.extend(cut_locations);
        let compiled = compiled.map_err(ImportError::Compile)?;
        Ok::<_, ImportError>((compiled, made))
    })?;
    let mut compiled = compiled;
    let compile_ms = t.elapsed().as_secs_f64() * 1e3;
    tracing::info!(
        compile_ms,
        peak_rss_bytes = crate::peak_rss_bytes(),
        "compiled"
    );
    crate::memory::log_phase("compile");
    for (i, m) in compiled.meshes.iter_mut().enumerate() {
        let at = if let Some(&at) = made_locations.get(&(i as u32)) {
            at
        } else if m.lod == 0 && m.flags & motu_abi::FLAG_PRIMITIVE_MAP == 0 {
            source_location(m)?
        } else {
            return Err(ImportError::Internal(format!(
                "compiled mesh record {i} (source mesh {}, LOD {}) was never stored",
                m.source_mesh, m.lod
            )));
        };
        place_mesh_record(m, at);
    }
    Ok((compiled, compile_ms))
}

/// Made meshes queued for the writer thread at most (each up to a cluster: ~2 MiB at 2^16
/// triangles).
const MADE_IN_FLIGHT: usize = 4;

/// Bytes of `.pbrt`/`.pbrt.gz` text under `dir` (bounded walk: 100k entries).
fn scene_text_bytes(dir: &Path) -> u64 {
    let mut total = 0u64;
    let mut seen = 0u32;
    let mut todo = vec![dir.to_path_buf()];
    while let Some(d) = todo.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in entries.flatten() {
            seen += 1;
            if seen > 100_000 {
                return total;
            }
            let p = e.path();
            match e.file_type() {
                Ok(t) if t.is_dir() => todo.push(p),
                Ok(t) if t.is_file() => {
                    let name = p.to_string_lossy();
                    if name.ends_with(".pbrt") || name.ends_with(".pbrt.gz") {
                        total += e.metadata().map_or(0, |m| m.len());
                    }
                }
                _ => {}
            }
        }
    }
    total
}

/// Refuses `output` if it is one of `inputs` (files a command read; checked after reading,
/// for inputs known only then, such as the PLY files a scene references).
fn check_not_an_input<'a>(
    option: &str,
    output: &Path,
    inputs: impl IntoIterator<Item = &'a Path>,
) -> Result<(), ImportError> {
    use motu_package::identity::FileIdentity;
    let Ok(m) = std::fs::symlink_metadata(output) else {
        return Ok(());
    };
    let id = FileIdentity::of(&m);
    for p in inputs {
        if FileIdentity::of_input(p).as_ref() == Some(&id) {
            return Err(ImportError::OutputIsInput {
                option: option.to_string(),
                output: output.to_path_buf(),
                input: p.to_path_buf(),
            });
        }
    }
    Ok(())
}
