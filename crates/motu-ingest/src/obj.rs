//! OBJ (+ MTL base colours) through tobj.

use crate::{IngestError, IngestReport};
use motu_scene::{GeometryStore, Material, MeshData, Scene, SceneBuilder};
use std::path::Path;

pub fn ingest_obj(
    path: &Path,
    geometry: Box<dyn GeometryStore>,
) -> Result<(Scene, IngestReport), IngestError> {
    let shown = path.display().to_string();
    let err = |reason: String| IngestError::Obj {
        path: shown.clone(),
        reason,
    };
    let (models, materials) = tobj::load_obj(
        path,
        &tobj::LoadOptions {
            triangulate: true,
            single_index: true,
            ..Default::default()
        },
    )
    .map_err(|e| err(e.to_string()))?;
    let mut report = IngestReport {
        files: 1,
        ..Default::default()
    };
    let mut b = SceneBuilder::new(geometry);
    let mut mat_ids = Vec::new();
    let dir = path.parent().unwrap_or(Path::new("."));
    match materials {
        Ok(ms) => {
            for m in ms {
                // MTL map names are relative to the OBJ; a missing file falls back to Kd.
                let mut texture = |name: &Option<String>, is_alpha: bool| {
                    let name = name.as_ref()?;
                    let file = dir.join(name);
                    if !file.is_file() {
                        report.warnings.push(format!(
                            "{shown}: texture file missing: {}; the material's constant colour is used",
                            file.display()
                        ));
                        return None;
                    }
                    Some(b.add_texture(motu_scene::Texture {
                        path: file,
                        is_alpha,
                    }))
                };
                let base_color_texture = texture(&m.diffuse_texture, false);
                let alpha_texture = texture(&m.dissolve_texture, true);
                // Phong exponent to roughness (Ns 0 → 1, Ns 1000 → ~0.06).
                let roughness = m
                    .shininess
                    .map_or(1.0, |ns| (2.0 / (ns.max(0.0) + 2.0)).sqrt().clamp(0.0, 1.0));
                let id = b
                    .add_material(Material {
                        name: m.name.clone(),
                        base_color: m.diffuse.unwrap_or([0.5; 3]),
                        opacity: m.dissolve.unwrap_or(1.0),
                        alpha_texture,
                        base_color_texture,
                        roughness,
                        ..Material::default()
                    })
                    .map_err(|e| IngestError::Scene {
                        at: shown.clone(),
                        source: e,
                    })?;
                mat_ids.push(id);
            }
        }
        Err(e) => report
            .warnings
            .push(format!("{shown}: materials not loaded: {e}")),
    }
    let scene_err = |e| IngestError::Scene {
        at: shown.clone(),
        source: e,
    };
    for model in models {
        let m = &model.mesh;
        report.shapes += 1;
        let positions: Vec<[f32; 3]> = m
            .positions
            .chunks_exact(3)
            .map(|p| [p[0], p[1], p[2]])
            .collect();
        let normals = (m.normals.len() == m.positions.len()).then(|| {
            m.normals
                .chunks_exact(3)
                .map(|n| [n[0], n[1], n[2]])
                .collect()
        });
        let uvs = (m.texcoords.len() / 2 == positions.len() && !m.texcoords.is_empty())
            .then(|| m.texcoords.chunks_exact(2).map(|t| [t[0], t[1]]).collect());
        let data = MeshData {
            positions,
            normals,
            uvs,
            indices: m.indices.clone(),
        };
        if data.indices.is_empty() {
            report.degenerate_meshes += 1;
            continue;
        }
        let mat = m
            .material_id
            .and_then(|i| mat_ids.get(i).copied())
            .unwrap_or(b.default_material());
        b.add_mesh(b.root(), &model.name, mat, Scene::MAIN_ELEMENT, &data)
            .map_err(scene_err)?;
        report.meshes += 1;
    }
    Ok((b.finish().map_err(scene_err)?, report))
}
