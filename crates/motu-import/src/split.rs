//! The stream split, made once at import and stored in the package (`motu report` reads it
//! instead of splitting a Moana-sized root again; FORMAT.md "stream split").

use crate::ImportError;
use motu_compile::CompiledScene;
use motu_package::PackageWriter;

/// Splits `compiled`'s TLASes over [`motu_compile::STREAM_SPLIT_INSTANCES`] as `motu render
/// --stream` does, writes the split's sections and returns the meta entry that describes
/// them. Split in place: the instance table is not copied (`compiled` ends as it was).
pub(crate) fn write_stream_split(
    writer: &mut PackageWriter,
    compiled: &mut CompiledScene,
) -> Result<motu_pack::StreamSplitMeta, ImportError> {
    let t = std::time::Instant::now();
    let cap = motu_compile::STREAM_SPLIT_INSTANCES;
    let stored =
        motu_compile::stored_stream_split_in_place(compiled, cap).map_err(ImportError::Compile)?;
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
        tlases = meta.tlases_split,
        pieces = meta.pieces,
        peak_rss_bytes = crate::peak_rss_bytes(),
        "stream split stored"
    );
    Ok(meta)
}
