//! The real scenes in /work/shared/scenes (skipped with a message when absent).

use std::path::{Path, PathBuf};

use pbrt_import::{
    parse_file, CollectSink, Error, Geometry, ParseOptions, PbrtVersion, SceneSink, ShapeEvent,
    SinkError,
};

fn scene(rel: &str) -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/scenes")
        .join(rel);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("SKIPPED: scene {} not present", p.display());
        None
    }
}

/// Counts shapes without keeping geometry.
#[derive(Default)]
struct Counting {
    triangles_per_shape: Vec<(usize, Option<pbrt_import::ObjectId>)>,
    instances: Vec<(String, [f32; 16])>,
    objects: Vec<String>,
    cameras: usize,
}

impl SceneSink for Counting {
    fn shape(&mut self, s: ShapeEvent) -> Result<(), SinkError> {
        if let Geometry::Mesh(m) = &s.geometry {
            self.triangles_per_shape
                .push((m.triangle_count(), s.object));
        }
        Ok(())
    }
    fn object_begin(&mut self, e: &pbrt_import::ObjectEvent<'_>) -> Result<(), SinkError> {
        self.objects.push(e.name.to_owned());
        Ok(())
    }
    fn object_instance(&mut self, e: &pbrt_import::InstanceEvent<'_>) -> Result<(), SinkError> {
        self.instances
            .push((e.name.to_owned(), e.parent_from_instance.to_cols_array()));
        Ok(())
    }
    fn camera(&mut self, _e: &pbrt_import::CameraEvent<'_>) -> Result<(), SinkError> {
        self.cameras += 1;
        Ok(())
    }
}

#[test]
fn buddha_fractal_counts() {
    let Some(path) = scene("buddha-fractal/buddha-fractal.pbrt") else {
        return;
    };
    let mut sink = Counting::default();
    let stats = parse_file(&path, &ParseOptions::default(), &mut sink).unwrap();
    assert_eq!(stats.version, Some(PbrtVersion::V3));
    assert_eq!(stats.instances, 25_250);
    assert_eq!(sink.instances.len(), 25_250);
    assert!(sink.instances.iter().all(|(n, _)| n == "Buddha_Mesh25251"));
    assert_eq!(sink.objects, ["Buddha_Mesh25251"]);
    // One 29,890-triangle PLY inside the object, one 2-triangle floor outside.
    let inside: Vec<_> = sink
        .triangles_per_shape
        .iter()
        .filter(|s| s.1.is_some())
        .collect();
    let outside: Vec<_> = sink
        .triangles_per_shape
        .iter()
        .filter(|s| s.1.is_none())
        .collect();
    assert_eq!(inside.len(), 1);
    assert_eq!(inside[0].0, 29_890);
    assert_eq!(outside.len(), 1);
    assert_eq!(outside[0].0, 2);
    assert_eq!(sink.cameras, 1);
    // First instance: Transform [1 0 0 0 0 1 0 0 0 0 1 0 11.5665998 2.08030009 28.5746002 1].
    assert_eq!(
        sink.instances[0].1[12],
        "11.5665998".parse::<f32>().unwrap()
    );
}

#[test]
fn buddha_fractal_sequential_ply_matches() {
    let Some(path) = scene("buddha-fractal/buddha-fractal.pbrt") else {
        return;
    };
    let opts = ParseOptions {
        ply_loading: pbrt_import::PlyLoading::Sequential,
        ..Default::default()
    };
    let mut sink = CollectSink::default();
    let stats = parse_file(&path, &opts, &mut sink).unwrap();
    assert_eq!(stats.triangles, 29_892);
    // Sequential loading keeps document order: the floor (seq 0) precedes the buddha (seq 1).
    assert_eq!(
        sink.shapes.iter().map(|s| s.seq).collect::<Vec<_>>(),
        [0, 1]
    );
    let buddha = &sink.shapes[1];
    assert_eq!(buddha.material.name.as_deref(), Some("Buda"));
    assert_eq!(
        buddha.material.base_color,
        Some(["0.81176502".parse::<f32>().unwrap(); 3])
    );
    let (_, cam) = &sink.cameras[0];
    assert_eq!(cam.resolution, [750, 1200]);
    assert_eq!(cam.fov_deg, Some(30.2642));
    assert_eq!(sink.lights.len(), 1);
}

#[test]
fn bmw_m6_parses() {
    let Some(path) = scene("bmw-m6/bmw-m6.pbrt") else {
        return;
    };
    let mut sink = CollectSink::default();
    let stats = parse_file(&path, &ParseOptions::default(), &mut sink).unwrap();
    assert!(stats.shapes > 10, "{stats:?}");
    assert!(stats.triangles > 100_000, "{stats:?}");
    assert_eq!(stats.cameras, 1);
    // Metal with spectrum files gets a colour from the .spd data.
    let silver = sink
        .materials
        .iter()
        .find(|m| m.name.as_deref() == Some("LogoSilver"))
        .unwrap();
    assert_eq!(silver.kind, "metal");
    let car = sink
        .materials
        .iter()
        .find(|m| m.name.as_deref() == Some("CarPaint"))
        .unwrap();
    assert_eq!(car.base_color, Some([0.4, 0.03, 0.03]));
    let leather = sink
        .materials
        .iter()
        .find(|m| m.name.as_deref() == Some("LEATHER"))
        .unwrap();
    assert!(leather.base_color.is_none(), "fourier half has no colour");
}

#[test]
fn ecosys_missing_plys_listed_then_allowed() {
    let Some(path) = scene("ecosys/ecosys.pbrt") else {
        return;
    };
    let err = parse_file(&path, &ParseOptions::default(), &mut CollectSink::default()).unwrap_err();
    let Error::MissingFiles { files } = &err else {
        panic!("expected MissingFiles, got {err}")
    };
    assert!(files.len() > 100, "{}", files.len());
    assert!(files
        .iter()
        .any(|f| f.path.ends_with("geometry/mesh_00001.ply")));
    assert!(err.to_string().contains("mesh_00002.ply"));
    let opts = ParseOptions {
        allow_missing: true,
        ..Default::default()
    };
    let mut sink = Counting::default();
    let stats = parse_file(&path, &opts, &mut sink).unwrap();
    assert_eq!(stats.instances, 4_817);
    assert_eq!(stats.objects, 61);
    assert_eq!(stats.missing.len(), files.len());
    assert!(stats.warnings as usize >= files.len());
}

#[test]
fn kroken_v4_structure() {
    let Some(path) = scene("kroken-v4/camera-1.pbrt") else {
        return;
    };
    let err = parse_file(&path, &ParseOptions::default(), &mut CollectSink::default()).unwrap_err();
    assert!(matches!(err, Error::MissingFiles { .. }), "{err}");
    let opts = ParseOptions {
        allow_missing: true,
        ..Default::default()
    };
    let mut sink = CollectSink::default();
    let stats = parse_file(&path, &opts, &mut sink).unwrap();
    assert_eq!(stats.version, Some(PbrtVersion::V4));
    assert_eq!(stats.files.len(), 4);
    assert!(stats.shapes > 10);
    assert_eq!(sink.cameras.len(), 1);
    assert_eq!(sink.cameras[0].0, "camera-1");
    assert_eq!(sink.cameras[0].1.resolution, [1500, 1500]);
    assert!(sink.lights.iter().any(|l| l.kind == "infinite"));
    // Files included from the world block are elements named by stem.
    let elems: Vec<_> = sink.files.iter().filter_map(|f| f.3.clone()).collect();
    assert_eq!(elems, ["lights", "materials", "geometry"]);
}
