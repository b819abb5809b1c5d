use std::borrow::Cow;

use motu_abi::camera::CameraPose;
use motu_compile::proxy_boxes::{blas_hash, encode_section, StoredProxyBoxes};
use motu_trace::testutil::{srt, uv_sphere, HierarchyBuilder, OwnedHierarchy};

use super::*;
use crate::testutil::{assert_no_validation_errors, context_or_skip};
use crate::{
    render, Backend, BuildOptions, GpuScene, MeshSourceError, RenderOptions, Requirement,
    StreamOptions, StreamingRenderer, View,
};

/// A mesh source with (or without) a stored proxy-box table.
struct WithTable<'a> {
    h: &'a OwnedHierarchy,
    section: Option<Vec<u8>>,
}

impl MeshBlobSource for WithTable<'_> {
    fn mesh_data(
        &self,
        mesh_record: u32,
    ) -> Result<(Cow<'_, [[f32; 3]]>, Cow<'_, [u32]>), MeshSourceError> {
        self.h.mesh_data(mesh_record)
    }

    fn stored_proxy_boxes(&self) -> Option<&[u8]> {
        self.section.as_deref()
    }
}

/// A row of spheres (fans 1 to 4) in front of the camera, each its own BLAS, and a BLAS of
/// two meshes.
fn scene() -> OwnedHierarchy {
    let mut b = HierarchyBuilder::new();
    let mat = b.material([0.6, 0.6, 0.6]);
    let mut instances = Vec::new();
    for i in 0..6u32 {
        let m = b.mesh(i, 0, mat, uv_sphere(6 + 4 * i));
        let blas = b.triangle_blas(&[m]);
        let x = (i as f32 - 2.5) * 2.1;
        instances.push((srt(1.0, 0.2 * i as f32, [x, 0.0, 0.0]), blas));
    }
    let a = b.mesh(6, 0, mat, uv_sphere(10));
    let c = b.mesh(7, 0, mat, uv_sphere(14));
    let pair = b.triangle_blas(&[a, c]);
    instances.push((srt(0.7, 0.0, [0.0, 1.6, -1.0]), pair));
    let root = b.tlas(&instances);
    b.finish(root)
}

/// The table `motu import` would store for `h` (every triangle BLAS), through its bytes.
fn stored_table(h: &OwnedHierarchy) -> StoredProxyBoxes {
    let view = h.view();
    let source = WithTable { h, section: None };
    let (index, total) = layout(&view, |_| true);
    let boxes = compute(&view, &source, &index, total);
    let mut t = StoredProxyBoxes::default();
    for (b, &[first, fan]) in index.iter().enumerate() {
        if fan != 0 {
            let n = (fan + fan * fan) as usize;
            t.push(
                b as u32,
                fan,
                blas_hash(&view, b),
                &boxes[first as usize..][..n],
            );
        }
    }
    t
}

#[test]
fn stored_entries_are_taken_where_they_match_and_made_where_they_do_not() {
    let h = scene();
    let view = h.view();
    let source = WithTable {
        h: &h,
        section: None,
    };
    let (index, total) = layout(&view, |b| view.blases[b].kind == BLAS_TRIANGLES);
    let made = compute(&view, &source, &index, total);
    let bits = |t: &[Box6]| t.iter().flatten().map(|v| v.to_bits()).collect::<Vec<_>>();
    let fans: Vec<u32> = index.iter().map(|ix| ix[1]).collect();
    assert!(fans.contains(&1) && fans.contains(&4), "{fans:?}");
    let stored = stored_table(&h);
    let (table, left, stale) = from_stored(&view, &stored, &index, total);
    assert_eq!((left.len(), stale), (0, 0));
    assert_eq!(bits(&table), bits(&made));
    // Two entries made for other records: those two are left (stale) and made again.
    let mut other = stored.clone();
    other.entries[1].hash ^= 1;
    other.entries[4].hash ^= 1;
    let (mut table, left, stale) = from_stored(&view, &other, &index, total);
    assert_eq!(stale, 2);
    assert_eq!(
        left,
        vec![
            other.entries[1].blas as usize,
            other.entries[4].blas as usize
        ]
    );
    assert_ne!(bits(&table), bits(&made));
    fill(&view, &source, &index, &mut table, &left);
    assert_eq!(bits(&table), bits(&made));
    // A table without an entry for a BLAS: absent, made, not stale.
    let mut fewer = stored.clone();
    fewer.entries.remove(0);
    let (_, left, stale) = from_stored(&view, &fewer, &index, total);
    assert_eq!((left.len(), stale), (1, 0));
}

/// Streamed frames whose boxes came from a stored table, a stale one and none are the full
/// build's, and the totals say where the boxes came from.
#[test]
fn stored_stale_and_absent_tables_stream_the_full_builds_image() {
    let Some(ctx) = context_or_skip("stream_stored_proxy_boxes", Requirement::RayTracing) else {
        return;
    };
    let h = scene();
    let stored = stored_table(&h);
    let mut stale = stored.clone();
    for e in &mut stale.entries {
        e.hash = !e.hash;
    }
    let plain = WithTable {
        h: &h,
        section: None,
    };
    let full = GpuScene::build(&ctx, &h.view(), &plain, &BuildOptions::default()).expect("full");
    let opts = RenderOptions {
        backend: Backend::best(&ctx).unwrap_or(Backend::Pipeline),
        view: View::Shaded,
        ..Default::default()
    };
    let cam = CameraPose {
        world_eye: [0.0, 0.5, 9.0].into(),
        world_forward: [0.0, -0.05, -1.0].into(),
        world_up: [0.0, 1.0, 0.0].into(),
        fov_deg: 60.0,
        mirror_x: false,
    }
    .params(32, 24);
    let reference = render(&ctx, &full, &cam, &opts).expect("full render");
    let hits = reference
        .aov
        .records
        .iter()
        .filter(|r| r.mesh != motu_abi::aov::MISS)
        .count();
    assert!(hits > 100, "the camera sees the spheres: {hits}");
    let budget = full.report().peak_bytes.max(64 << 20);
    for (name, table, source, stale_blases) in [
        ("stored", Some(&stored), "package", 0),
        (
            "stale",
            Some(&stale),
            "computed",
            stored.entries.len() as u64,
        ),
        ("none", None, "computed", 0),
    ] {
        let blobs = WithTable {
            h: &h,
            section: table.map(encode_section),
        };
        let mut sr = StreamingRenderer::new(
            &ctx,
            h.view(),
            &blobs,
            &StreamOptions {
                budget_bytes: budget,
                staging_bytes: 256 * 1024,
                scratch_budget_bytes: 1 << 20,
                ..Default::default()
            },
        )
        .expect("streaming renderer");
        let totals = sr.totals();
        assert_eq!(totals.proxy_boxes_source, source, "{name}");
        assert_eq!(totals.proxy_boxes_stale_blases, stale_blases, "{name}");
        let (out, st) = sr.render_frame(&cam, &opts).expect("frame");
        assert!(st.complete, "{name}: {st:?}");
        let cmp = motu_trace::compare(&reference.aov, &out.aov, 0.0).expect("sizes");
        assert_eq!(cmp.mismatched, 0, "{name}: {cmp:?}");
    }
    assert_no_validation_errors(&ctx);
}
