//! Light files (`json/lights/…`): each light a quad, dome or distant light event.

use std::path::Path;

use super::json::Node;
use super::Importer;
use crate::events::LightEvent;
use crate::math;
use crate::{Error, Location};

impl Importer<'_> {
    pub(super) fn lights(
        &mut self,
        path: &Path,
        referenced_at: Option<&Location>,
    ) -> Result<(), Error> {
        let Some(input) = self.open(path, referenced_at, None)? else {
            return Ok(());
        };
        let doc = input.tree()?;
        for (name, l) in doc.members() {
            let vec3 = |key: &str| -> Result<Option<[f64; 3]>, Error> {
                let Some(n) = l.get(key) else { return Ok(None) };
                let v: Vec<f64> = n.items().iter().filter_map(Node::as_f64).collect();
                if v.len() < 3 || v[..3].iter().any(|x| !x.is_finite()) {
                    return Err(input.invalid(
                        n.at,
                        format!("light `{name}`: `{key}` must be 3 finite numbers"),
                    ));
                }
                Ok(Some([v[0], v[1], v[2]]))
            };
            let exposure = l.get("exposure").and_then(Node::as_f64).unwrap_or(0.0);
            let gain = 2f64.powf(exposure);
            let color = vec3("color")?.unwrap_or([1.0; 3]);
            let world_from_light = Self::matrix(
                &input,
                l.get("translationMatrix"),
                &format!("light `{name}` translationMatrix"),
            )?;
            let kind = l.get("type").and_then(Node::as_str).unwrap_or("");
            let f = |v: [f64; 3]| v.map(|x| x as f32);
            let event = match kind {
                "distant" => LightEvent {
                    kind: "distant".into(),
                    world_from_light: math::to_f32(&world_from_light),
                    color: Some(f(color.map(|c| c * gain))),
                    from: vec3("from")?.map(f),
                    to: vec3("to")?.map(f),
                    map: None,
                    map_path: None,
                    cone_deg: None,
                    object: None,
                    element: None,
                    loc: input.loc(l.at),
                },
                "quad" => {
                    // An area light as a point light of its power at its centre.
                    let w = l.get("width").and_then(Node::as_f64).unwrap_or(1.0);
                    let h = l.get("height").and_then(Node::as_f64).unwrap_or(1.0);
                    let area = (w * h).abs();
                    LightEvent {
                        kind: "point".into(),
                        world_from_light: math::to_f32(&world_from_light),
                        color: Some(f(color.map(|c| c.powf(2.2) * gain * area))),
                        from: Some([0.0; 3]),
                        to: None,
                        map: None,
                        map_path: None,
                        cone_deg: None,
                        object: None,
                        element: None,
                        loc: input.loc(l.at),
                    }
                }
                "dome" => {
                    let map = l.get("map").and_then(Node::as_str).map(str::to_string);
                    let map_path = map.as_ref().map(|m| self.resolve(m, &input.path));
                    LightEvent {
                        kind: "infinite".into(),
                        world_from_light: math::to_f32(&world_from_light),
                        color: Some(f([gain; 3])),
                        from: None,
                        to: None,
                        map,
                        map_path,
                        cone_deg: None,
                        object: None,
                        element: None,
                        loc: input.loc(l.at),
                    }
                }
                other => {
                    self.warn(
                        Some(input.loc(l.at)),
                        format!("light `{name}` has type `{other}` (quad, dome and distant are read); skipped"),
                    );
                    continue;
                }
            };
            self.stats.lights += 1;
            self.sink.light(&event)?;
        }
        Ok(())
    }
}
