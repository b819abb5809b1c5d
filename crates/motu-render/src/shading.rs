//! How the shaded view is lit: the scene's lights, the sky and ambient occlusion.

use glam::Vec3;
use motu_abi::HierarchyView;
use motu_pack::ScenePackage;

/// How far ambient-occlusion rays reach, as a fraction of the scene's diagonal.
pub const AO_DISTANCE_OF_DIAGONAL: f32 = 0.2;

/// The sampling and exposure options of the shaded view (`--ao-samples`, `--spp`,
/// `--exposure`); `Default` is `motu render`'s defaults (the viewer and flights use them).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadingOptions {
    pub ao_samples: u32,
    pub spp: u32,
    /// `--exposure EV` (used when `auto_exposure` is off).
    pub exposure_ev: f32,
    /// `--exposure auto` (the default): from the image's log-average luminance.
    pub auto_exposure: bool,
    /// `--bounces N`: diffuse bounces after each camera hit (every renderer, streaming
    /// included).
    pub bounces: u32,
    /// `--ao-reach F`: ambient-occlusion rays reach F × the scene's diagonal (default
    /// [`AO_DISTANCE_OF_DIAGONAL`]). Shorter reach: AO rays meet fewer far structures, so a
    /// streamed frame's working set shrinks; the image changes (compare against a full build
    /// with the same setting).
    pub ao_reach_of_diagonal: f32,
}

impl Default for ShadingOptions {
    fn default() -> Self {
        ShadingOptions {
            ao_samples: 1,
            spp: 1,
            exposure_ev: 0.0,
            auto_exposure: true,
            bounces: 1,
            ao_reach_of_diagonal: AO_DISTANCE_OF_DIAGONAL,
        }
    }
}

/// How the shaded view is lit: the scene's lights (the brightest `MAX_LIGHTS`; infinite
/// lights become the sky colour), ambient occlusion reaching `ao_reach_of_diagonal` (default
/// [`AO_DISTANCE_OF_DIAGONAL`]) of the scene's diagonal, and the sampling and exposure options. A scene without lights gets the
/// renderers' key light and sky.
pub fn scene_shading(
    o: ShadingOptions,
    pkg: &ScenePackage,
    view: &HierarchyView<'_>,
) -> motu_abi::shade::Shading {
    let ShadingOptions {
        ao_samples,
        spp,
        exposure_ev: exposure,
        auto_exposure,
        bounces,
        ao_reach_of_diagonal,
    } = o;
    use motu_abi::shade::{
        Shading, LIGHT_AREA, LIGHT_DISTANT, LIGHT_POINT, LIGHT_SPOT, MAX_LIGHTS,
    };
    use motu_scene::LightKind;
    let mut sh = Shading {
        ao_samples,
        spp: spp.max(1),
        exposure_ev: exposure,
        auto_exposure,
        bounces,
        ..Default::default()
    };
    if let Some(root) = view.tlases.get(view.root_tlas as usize) {
        let d = Vec3::from_array(root.bounds_max) - Vec3::from_array(root.bounds_min);
        if d.is_finite() && d.length() > 0.0 {
            sh.ao_distance = ao_reach_of_diagonal * d.length();
        }
    }
    let mut lights = Vec::new();
    let mut sky: Option<[f32; 3]> = None;
    let mut skipped = 0usize;
    for l in &pkg.meta().lights {
        let radiance = l.color.map(|c| c * l.intensity);
        let rec = motu_abi::LightRecord {
            world_position: l.world_position,
            world_direction: Vec3::from_array(l.world_direction)
                .normalize_or(Vec3::NEG_Y)
                .to_array(),
            radiance,
            ..Default::default()
        };
        let rec = match l.kind {
            LightKind::Distant => motu_abi::LightRecord {
                kind: LIGHT_DISTANT,
                ..rec
            },
            LightKind::Point => motu_abi::LightRecord {
                kind: LIGHT_POINT,
                ..rec
            },
            LightKind::Spot => {
                let [cone, delta] = l.cone_deg.unwrap_or([30.0, 5.0]);
                motu_abi::LightRecord {
                    kind: LIGHT_SPOT,
                    cos_total: cone.to_radians().cos(),
                    cos_falloff: (cone - delta).max(0.0).to_radians().cos(),
                    ..rec
                }
            }
            LightKind::Area => motu_abi::LightRecord {
                kind: LIGHT_AREA,
                cos_total: l.radius,
                ..rec
            },
            LightKind::Infinite => {
                if let (Some(map), None) = (&l.map, sh.environment) {
                    // The first environment map lights as itself; its mean stays the sky
                    // colour (fallbacks, `--ao-samples 0`).
                    sh.environment = motu_abi::env::Environment::new(
                        map.width,
                        map.height,
                        map.radiance.clone(),
                        map.world_from_light,
                    )
                    .map(motu_abi::env::Environment::intern);
                    if sh.environment.is_none() {
                        eprintln!("warning: an environment map's size or orientation is invalid; its mean colour lights the scene");
                    }
                } else if l.map.is_some() {
                    eprintln!("warning: the scene has several environment maps; only the first is sampled (the others count in the unoccluded sky term of --ao-samples 0 only)");
                }
                let s = sky.get_or_insert([0.0; 3]);
                for (s, r) in s.iter_mut().zip(radiance) {
                    *s += r;
                }
                continue;
            }
            LightKind::Other => {
                skipped += 1;
                continue;
            }
        };
        lights.push(rec);
    }
    if skipped > 0 {
        eprintln!("warning: {skipped} light(s) of a kind motu does not shade (goniometric, projection, ...) left out");
    }
    if lights.len() > MAX_LIGHTS {
        let peak = |r: &motu_abi::LightRecord| r.radiance.iter().cloned().fold(0.0f32, f32::max);
        lights.sort_by(|x, y| peak(y).total_cmp(&peak(x)));
        eprintln!(
            "warning: the scene has {} lights; shading with the {MAX_LIGHTS} brightest",
            lights.len()
        );
        lights.truncate(MAX_LIGHTS);
    }
    if lights.is_empty() && sky.is_some() {
        // Sky light only: no key light (the sky term lights the scene).
        lights.push(motu_abi::LightRecord {
            kind: LIGHT_DISTANT,
            world_direction: [0.0, -1.0, 0.0],
            radiance: [0.0; 3],
            ..Default::default()
        });
    }
    for (i, l) in lights.iter().enumerate() {
        sh.lights[i] = *l;
    }
    sh.light_count = lights.len() as u32;
    sh.sky = sky;
    sh
}
