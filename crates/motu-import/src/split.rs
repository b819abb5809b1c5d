//! The stream split, made once at import and stored in the package (`motu report` reads it
//! instead of splitting a Moana-sized root again; FORMAT.md "stream split"), and the proxy
//! clusters of the split hierarchy's TLASes (the `proxy_clusters` section), which streamed
//! starts and the floor read instead of making them.

use crate::ImportError;
use motu_abi::HierarchyView;
use motu_compile::{proxy_clusters, CompiledScene, StoredStreamSplit, StreamSplit};
use motu_package::PackageWriter;

/// Splits `compiled`'s TLASes over `cap` instances (`--stream-split-instances`, by default
/// [`motu_compile::STREAM_SPLIT_INSTANCES`]; 0: none) as `motu render --stream` does, writes
/// the split's sections and returns the meta entry that describes them (with the cap: the
/// renderer's default for this package), and the split (`None`: no TLAS over the cap). Split
/// in place: the instance table is not copied; the split holds it until
/// [`motu_compile::StreamSplit::give_back`] (`compiled.instances` is empty until then).
/// A large TLAS is split by key, its records in an unnamed file in `scratch_dir` meanwhile
/// (the same split without the table and the partition's arrays resident together).
/// The package's instance table (of at least [`motu_compile::PARK_MIN_INSTANCES`]) is first
/// written to an unnamed file there and returned mapped: the split is then dropped instead of
/// given back, and `compiled.instances` stays empty (issue 48 item 1: no table comes back to
/// the heap for the package's last sections).
pub(crate) fn write_stream_split(
    writer: &mut PackageWriter,
    compiled: &mut CompiledScene,
    cap: u32,
    scratch_dir: &std::path::Path,
) -> Result<StreamSplitWritten, ImportError> {
    let t = std::time::Instant::now();
    let table =
        motu_compile::park_table(&compiled.instances, scratch_dir).map_err(ImportError::Compile)?;
    let mut split = if cap == 0 {
        None
    } else {
        motu_compile::stream_split_taking_instances_in(compiled, cap, Some(scratch_dir))
            .map_err(ImportError::Compile)?
    };
    if table.is_some() {
        // The map holds the table in the package's order; a split took the heap's copy.
        compiled.instances = Default::default();
    }
    let mut parked = false;
    if let Some((_, s)) = &mut split {
        // The split's table off the heap while the proxy tables are made over it (issue 48
        // item 1): the clusters read it a batch at a time, dropping its pages behind.
        parked = s
            .park_instances(scratch_dir)
            .map_err(ImportError::Compile)?;
    }
    let stored = split.as_ref().map(|(s, _)| s);
    let mut meta = motu_pack::StreamSplitMeta {
        cap_instances: cap,
        tlases_split: 0,
        pieces: 0,
    };
    if let Some(s) = &stored {
        meta.tlases_split = s.tlases_split;
        meta.pieces = s.pieces;
        motu_pack::write_stream_split(
            writer,
            &motu_pack::StreamSplitTables {
                tlases: &s.tlases,
                blases: &s.blases,
                pis: &s.pis,
                instance_source: &s.instance_source,
                extra_instances: &s.extra_instances,
            },
        )?;
    }
    tracing::info!(
        split_ms = t.elapsed().as_secs_f64() * 1e3,
        cap,
        tlases = meta.tlases_split,
        pieces = meta.pieces,
        parked,
        table_parked = table.is_some(),
        peak_rss_bytes = crate::peak_rss_bytes(),
        "stream split stored"
    );
    Ok(StreamSplitWritten { meta, split, table })
}

/// What [`write_stream_split`] returns: the meta entry, the split (`None`: no TLAS over the
/// cap) and the package's instance table when it was moved to a mapped file.
pub(crate) struct StreamSplitWritten {
    pub meta: motu_pack::StreamSplitMeta,
    pub split: Option<(StoredStreamSplit, StreamSplit)>,
    pub table: Option<motu_compile::InstanceMap>,
}

/// Makes the proxy clusters of every TLAS of `streamed` (the hierarchy a streamed render draws:
/// the package's with the stream split just stored) and adds them as the package's
/// `proxy_clusters` section (FORMAT.md), so neither a streamed start nor `motu report`'s floor
/// runs the binned SAH over every instance.
/// `release` drops the pages of a mapped instance table read so far (called after each batch).
pub(crate) fn write_proxy_clusters(
    writer: &mut PackageWriter,
    streamed: &HierarchyView<'_>,
    release: &dyn Fn(),
) -> Result<(), ImportError> {
    let t = std::time::Instant::now();
    // Made a batch of TLASes at a time and written piece by piece: no TLAS's cluster list
    // outlives its batch, and the section's bytes are not copied out of the table (each would
    // sit beside the instance table at the import's peak: issue 48 item 1).
    let table = proxy_clusters::StoredProxyClusters::of_view_then(streamed, &mut || release());
    release();
    let made_ms = t.elapsed().as_secs_f64() * 1e3;
    let mut section =
        writer.begin_section(motu_pack::SECTION_PROXY_CLUSTERS, "proxy_clusters", 1)?;
    proxy_clusters::write_section(&table, |piece| section.write(piece))?;
    section.finish()?;
    tracing::info!(
        section = "proxy_clusters",
        section_bytes = proxy_clusters::section_bytes(&table),
        made_ms,
        counts = %format!("tlases={} clusters={}", table.tlases.len(), table.clusters.len()),
        "derived section stored"
    );
    Ok(())
}

/// Counts, per TLAS of the package's own hierarchy, the BLASes its instances place
/// (`motu_compile::blas_counts`) and adds them as the package's `blas_counts` section
/// (FORMAT.md), so `motu report` walks those entries instead of every instance.
/// `release` drops the pages of a mapped instance table read so far (called after each batch).
pub(crate) fn write_blas_counts(
    writer: &mut PackageWriter,
    view: &HierarchyView<'_>,
    release: &dyn Fn(),
) -> Result<(), ImportError> {
    add_timed_section(
        writer,
        motu_pack::SECTION_BLAS_COUNTS,
        "blas_counts",
        |_| {
            let counts = motu_compile::blas_counts::BlasCounts::of_then(view, &mut || release());
            release();
            let bytes = motu_compile::blas_counts::encode_section(view, &counts);
            let logged = format!(
                "tlases={} entries={}",
                view.tlases.len(),
                counts.entries.len()
            );
            Ok((bytes, logged))
        },
    )
}

/// Makes a derived section with `make` (its bytes and the counts its log line names, as
/// `key=value` words; `make` may read back what `writer` holds), adds it to the package as
/// `name` (one-byte elements) and logs how long making it took and its size: the one shape of
/// every table import derives and stores (`blas_counts`, `proxy_boxes`; `proxy_clusters` is
/// written piece by piece with the same log line).
pub(crate) fn add_timed_section(
    writer: &mut PackageWriter,
    kind: motu_package::SectionKind,
    name: &'static str,
    make: impl FnOnce(&PackageWriter) -> Result<(Vec<u8>, String), ImportError>,
) -> Result<(), ImportError> {
    let t = std::time::Instant::now();
    let (bytes, counts) = make(writer)?;
    let made_ms = t.elapsed().as_secs_f64() * 1e3;
    writer.add_section(kind, name, 1, &bytes)?;
    tracing::info!(
        section = name,
        section_bytes = bytes.len(),
        made_ms,
        counts = %counts,
        "derived section stored"
    );
    Ok(())
}
