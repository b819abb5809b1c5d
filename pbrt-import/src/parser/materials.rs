//! Appearance: lights, materials and textures, with each pbrt version's parameter semantics
//! (names, defaults, spectra and colours reduced to linear RGB).

use super::*;

/// Material types of pbrt-v3 and pbrt-v4 (others are warned about, then shaded as defaults).
const KNOWN_MATERIALS: &[&str] = &[
    "",
    "none",
    "interface",
    "matte",
    "diffuse",
    "coateddiffuse",
    "substrate",
    "disney",
    "translucent",
    "diffusetransmission",
    "subsurface",
    "kdsubsurface",
    "hair",
    "plastic",
    "uber",
    "mirror",
    "glass",
    "dielectric",
    "thindielectric",
    "coatedconductor",
    "metal",
    "conductor",
    "mix",
    "measured",
    "fourier",
];

/// Spectrum files are a few hundred (wavelength, value) pairs; a bigger one is not one.
const SPECTRUM_FILE_MAX_BYTES: u64 = 64 << 20;

impl<'s> Parser<'s> {
    /// `L`/`I` times `scale` (v3: spectrum scale; v4: float scale).
    pub(super) fn emission(&mut self, p: &ParamList<'_>, name: &str) -> Option<[f32; 3]> {
        let base = match p.get(name) {
            Some(param) => self.color_of(param)?.0,
            None => [1.0; 3],
        };
        let scale = match p.get("scale") {
            Some(param) if param.ty == ParamType::Float => p.float("scale").map(|s| [s; 3]),
            Some(param) => self.color_of(param).map(|c| c.0),
            None => None,
        }
        .unwrap_or([1.0; 3]);
        Some([base[0] * scale[0], base[1] * scale[1], base[2] * scale[2]])
    }

    pub(super) fn light<'b>(&mut self, lx: &mut Lexer<'b>, tok: &Token<'b>) -> Result<()> {
        self.require_world(tok);
        let (kind, _) = self.string(lx, tok)?;
        let p = self.params(lx)?;
        self.require_finite("LightSource", &p)?;
        let which = if p.get("I").is_some() { "I" } else { "L" };
        let color = self.emission(&p, which);
        let pt = |n: &str| {
            p.nums(n)
                .filter(|v| v.len() == 3)
                .map(|v| [v[0], v[1], v[2]])
        };
        let ev = LightEvent {
            world_from_light: math::to_f32(&self.xs.ctm[0]),
            color,
            from: pt("from"),
            to: pt("to"),
            map: p
                .string("mapname")
                .or(p.string("filename"))
                .map(str::to_owned),
            map_path: p
                .string("mapname")
                .or(p.string("filename"))
                .map(|f| self.resolve(f)),
            cone_deg: (kind == "spot").then(|| {
                [
                    p.float("coneangle").unwrap_or(30.0),
                    p.float("conedelta").unwrap_or(5.0),
                ]
            }),
            object: self.current_object,
            element: self.element,
            loc: tok.loc,
            kind: kind.into_owned(),
        };
        self.stats.lights += 1;
        self.sink.light(&ev)?;
        Ok(())
    }

    // ---- colours, textures, materials ----------------------------------------------------

    /// A colour from a parameter; the second value names a texture it came from.
    pub(super) fn color_of(&mut self, p: &Param<'_>) -> Option<([f32; 3], Option<String>)> {
        match (&p.values, p.ty) {
            (Values::Nums(v), ParamType::Rgb) if v.len() >= 3 => Some(([v[0], v[1], v[2]], None)),
            (Values::Nums(v), ParamType::Xyz) if v.len() >= 3 => {
                Some((color::xyz_to_rgb([v[0], v[1], v[2]]), None))
            }
            (Values::Nums(v), ParamType::Blackbody) if !v.is_empty() => {
                let scale = if v.len() >= 2 && !self.v4() {
                    v[1]
                } else {
                    1.0
                };
                if v.len() == 1 {
                    self.hint_v4("one-value blackbody");
                }
                Some((color::blackbody_rgb(v[0]).map(|c| c * scale), None))
            }
            (Values::Nums(v), ParamType::Spectrum) => {
                let pairs: Vec<(f32, f32)> = v.chunks_exact(2).map(|c| (c[0], c[1])).collect();
                color::spectrum_rgb(&pairs).map(|c| (c, None))
            }
            (Values::Nums(v), ParamType::Float) => v.first().map(|&f| ([f; 3], None)),
            (Values::Strs(s), ParamType::Spectrum) => {
                let name = s.first()?.to_string();
                let path = self.resolve(&name);
                if let Some(c) = self.spectrum_cache.get(&path) {
                    return c.map(|c| (c, None));
                }
                // Checked first: a FIFO or device named as a spectrum file must not be read.
                let read = crate::source::check_input(&path, Some(SPECTRUM_FILE_MAX_BYTES))
                    .and_then(|_| std::fs::read(&path));
                let rgb = match read {
                    Ok(bytes) => {
                        color::parse_spd(&bytes).and_then(|pairs| color::spectrum_rgb(&pairs))
                    }
                    Err(_) => None,
                };
                if rgb.is_none() {
                    self.warn_once(
                        &format!("spd:{name}"),
                        Some(p.loc),
                        format!(
                            "spectrum \"{name}\" is not a readable spectrum file; colour unknown"
                        ),
                    );
                }
                self.spectrum_cache.insert(path, rgb);
                rgb.map(|c| (c, None))
            }
            (Values::Strs(s), ParamType::Texture) => {
                let name = s.first()?;
                let rgb = self
                    .color_textures
                    .get(name.as_ref())
                    .or_else(|| self.float_textures.get(name.as_ref()))
                    .copied();
                match rgb {
                    Some(c) => Some((c, Some(name.to_string()))),
                    None => {
                        let n = name.to_string();
                        self.warn_once(
                            &format!("tex:{n}"),
                            Some(p.loc),
                            format!("unknown texture \"{n}\"; grey"),
                        );
                        Some(([0.5; 3], Some(n)))
                    }
                }
            }
            _ => None,
        }
    }

    /// The image behind a texture-valued parameter, if it names an image texture.
    pub(super) fn image_of(&self, p: &Param<'_>) -> Option<(PathBuf, [f32; 3])> {
        let Values::Strs(v) = &p.values else {
            return None;
        };
        if p.ty != ParamType::Texture {
            return None;
        }
        let n = v.first()?.to_string();
        self.image_textures
            .get(&(false, n.clone()))
            .or_else(|| self.image_textures.get(&(true, n)))
            .cloned()
    }

    /// A scalar parameter (a float, or a texture's constant value).
    fn scalar_of(&mut self, p: &ParamList<'_>, key: &str) -> Option<f32> {
        let param = p.get(key)?;
        self.color_of(param)
            .map(|c| (c.0[0] + c.0[1] + c.0[2]) / 3.0)
    }

    /// A material's parameters before it is made: non-finite numbers are errors at the
    /// parameter (they would reach shading and the package's JSON); negative colour values,
    /// which pbrt-v3 accepts, and unknown material types, are warnings with the location.
    pub(super) fn check_material(
        &mut self,
        directive: &str,
        kind: &str,
        p: &ParamList<'_>,
        loc: Loc,
    ) -> Result<()> {
        self.require_finite(directive, p)?;
        for param in &p.params {
            let colour = matches!(param.ty, ParamType::Rgb);
            if let (true, Values::Nums(v)) = (colour, &param.values) {
                if let Some(bad) = v.iter().find(|x| **x < 0.0) {
                    self.warn(
                        Some(param.loc),
                        format!(
                            "{directive} \"{kind}\" parameter \"{} {}\" has the negative value {bad}; a reflectance is 0–1 (shaded as given)",
                            param.ty.name(),
                            param.name
                        ),
                    );
                }
            }
        }
        if !KNOWN_MATERIALS.contains(&kind) {
            self.warn(
                Some(loc),
                format!(
                    "{directive}: unknown material type \"{kind}\"; shaded with default values"
                ),
            );
        }
        Ok(())
    }

    pub(super) fn make_material(
        &mut self,
        name: Option<String>,
        kind: &str,
        p: &ParamList<'_>,
        loc: Loc,
    ) -> Arc<Material> {
        let id = MaterialId(self.next_material);
        self.next_material += 1;
        let mut base_color = None;
        let mut base_color_texture = None;
        let mut base_color_image = None;
        let mut ptex = None;
        let colour_keys: &[&str] = match kind {
            "glass" | "dielectric" | "thindielectric" => &["Kt", "Kr"],
            _ => &["Kd", "reflectance", "color", "Kr"],
        };
        for &key in colour_keys {
            if let Some(param) = p.get(key) {
                if let Some((c, tex)) = self.color_of(param) {
                    base_color = Some(c);
                    base_color_texture = tex;
                    if let Some((path, factor)) = self.image_of(param) {
                        base_color = Some(factor);
                        base_color_image = Some(path);
                    }
                    if let (ParamType::Texture, Values::Strs(v)) = (&param.ty, &param.values) {
                        ptex = v
                            .first()
                            .and_then(|n| self.ptex_textures.get(n.as_ref()))
                            .cloned();
                    }
                    break;
                }
            }
        }
        // Roughness: v3 `roughness` (or the mean of `uroughness`/`vroughness`), v4 likewise.
        let mut roughness = self.scalar_of(p, "roughness").or_else(|| {
            let u = self.scalar_of(p, "uroughness")?;
            let v = self.scalar_of(p, "vroughness").unwrap_or(u);
            Some(0.5 * (u + v))
        });
        let mut metallic = self.scalar_of(p, "metallic");
        if kind == "mix" {
            // The dominant side (amount < 0.5: the first material), whole.
            let names: Vec<String> = match p.get("materials").map(|p| &p.values) {
                Some(Values::Strs(v)) => v.iter().map(|s| s.to_string()).collect(),
                _ => ["namedmaterial1", "namedmaterial2"]
                    .iter()
                    .filter_map(|k| p.string(k).map(str::to_owned))
                    .collect(),
            };
            let amount = self.scalar_of(p, "amount").unwrap_or(0.5);
            let pick = if amount < 0.5 { 0 } else { 1 };
            let side = names
                .get(pick)
                .or(names.first())
                .and_then(|n| self.named_materials.get(n))
                .cloned();
            if let Some(m) = side {
                if base_color.is_none() {
                    base_color = m.base_color;
                    base_color_texture = m.base_color_texture.clone();
                    base_color_image = m.base_color_image.clone();
                    ptex = m.ptex.clone();
                }
                roughness = roughness.or(m.roughness);
                metallic = metallic.or(m.metallic);
            }
        }
        let is_metal = matches!(kind, "metal" | "conductor");
        if base_color.is_none() && is_metal {
            base_color = Some(self.metal_colour(p));
        }
        if base_color.is_none() {
            base_color = match kind {
                "matte"
                | "diffuse"
                | "coateddiffuse"
                | "substrate"
                | "disney"
                | "translucent"
                | "diffusetransmission"
                | "subsurface"
                | "kdsubsurface"
                | "hair" => Some([0.5; 3]),
                "plastic" | "uber" => Some([0.25; 3]),
                "mirror" => Some([0.9; 3]),
                "glass" | "dielectric" | "thindielectric" => Some([1.0; 3]),
                "coatedconductor" => Some(self.metal_colour(p)),
                _ => None,
            };
        }
        if matches!(kind, "glass" | "dielectric" | "thindielectric") {
            // Shown as dark gloss (no refraction here): a little of the transmitted colour.
            base_color = base_color.map(|c| c.map(|v| 0.15 * v));
        }
        let roughness = roughness
            .or(match kind {
                "matte" | "diffuse" | "translucent" | "diffusetransmission" => Some(1.0),
                "plastic" | "substrate" | "uber" | "metal" => Some(0.1),
                "disney" => Some(0.5),
                "mirror" | "glass" | "dielectric" | "thindielectric" | "coateddiffuse" => Some(0.0),
                "conductor" | "coatedconductor" => Some(0.0),
                _ => None,
            })
            .map(|r| r.clamp(0.0, 1.0));
        let metallic = metallic
            .or(match kind {
                "metal" | "conductor" | "mirror" | "coatedconductor" => Some(1.0),
                "mix" | "interface" | "" | "none" => None,
                _ => Some(0.0),
            })
            .map(|m| m.clamp(0.0, 1.0));
        let opacity = p.get("opacity").and_then(|o| self.color_of(o)).map(|c| c.0);
        Arc::new(Material {
            id,
            name,
            kind: kind.to_owned(),
            base_color,
            base_color_texture,
            opacity,
            base_color_image,
            ptex,
            roughness,
            metallic,
            loc,
        })
    }

    /// A conductor's colour: `reflectance` (v4), else normal-incidence Fresnel of `eta`/`k`
    /// (RGB, or the usual named metal spectra), else copper (pbrt's default).
    fn metal_colour(&mut self, p: &ParamList<'_>) -> [f32; 3] {
        const COPPER: [f32; 3] = [0.955, 0.638, 0.538];
        let named = |s: &str| -> Option<[f32; 3]> {
            let s = s.to_ascii_lowercase();
            let table: [(&str, [f32; 3]); 7] = [
                ("cuzn", [0.887, 0.789, 0.434]),
                ("au", [1.0, 0.766, 0.336]),
                ("ag", [0.972, 0.960, 0.915]),
                ("al", [0.913, 0.922, 0.924]),
                ("cu", COPPER),
                ("mgo", [0.08, 0.08, 0.08]),
                ("tio2", [0.2, 0.2, 0.2]),
            ];
            table
                .iter()
                .find(|(k, _)| s.contains(&format!("-{k}-")) || s.starts_with(&format!("{k}-")))
                .map(|(_, c)| *c)
        };
        for key in ["eta", "k"] {
            if let Some(Param {
                values: Values::Strs(v),
                ..
            }) = p.get(key)
            {
                if let Some(c) = v.first().and_then(|s| named(s)) {
                    return c;
                }
            }
        }
        let eta = p.get("eta").and_then(|x| self.color_of(x)).map(|c| c.0);
        let k = p.get("k").and_then(|x| self.color_of(x)).map(|c| c.0);
        match (eta, k) {
            (Some(n), Some(k)) => std::array::from_fn(|i| {
                let (n, k) = (n[i], k[i]);
                (((n - 1.0) * (n - 1.0) + k * k) / ((n + 1.0) * (n + 1.0) + k * k)).clamp(0.0, 1.0)
            }),
            _ => COPPER,
        }
    }

    pub(super) fn texture<'b>(&mut self, lx: &mut Lexer<'b>, tok: &Token<'b>) -> Result<()> {
        let (name, ntok) = self.string(lx, tok)?;
        let (ty, ttok) = self.string(lx, tok)?;
        let (class, _) = self.string(lx, tok)?;
        let p = self.params(lx)?;
        let is_float = match ty.as_ref() {
            "float" => true,
            "color" | "spectrum" | "rgb" => false,
            _ => {
                return Err(self.err(
                    &ttok,
                    ParseErrorKind::Invalid("texture type must be float, color or spectrum".into()),
                ))
            }
        };
        let operand = |this: &mut Self, key: &str, default: f32| -> [f32; 3] {
            p.get(key)
                .and_then(|param| this.color_of(param))
                .map(|c| c.0)
                .unwrap_or([default; 3])
        };
        // The image (and its constant factor) behind a texture-valued operand.
        let image_of = |this: &Self, key: &str| -> Option<(PathBuf, [f32; 3])> {
            let param = p.get(key)?;
            let Values::Strs(v) = &param.values else {
                return None;
            };
            let n = v.first()?.to_string();
            this.image_textures
                .get(&(false, n.clone()))
                .or_else(|| this.image_textures.get(&(true, n)))
                .cloned()
        };
        let avg =
            |a: [f32; 3], b: [f32; 3]| -> [f32; 3] { std::array::from_fn(|i| 0.5 * (a[i] + b[i])) };
        let mul = |a: [f32; 3], b: [f32; 3]| -> [f32; 3] { std::array::from_fn(|i| a[i] * b[i]) };
        let mut image: Option<(PathBuf, [f32; 3])> = None;
        let mut ptex: Option<PathBuf> = None;
        let value = match class.as_ref() {
            "constant" => operand(self, "value", 1.0),
            "imagemap" => {
                let file = p.string("filename").unwrap_or("").to_owned();
                let path = self.resolve(&file);
                let scale = p.float("scale").unwrap_or(1.0);
                let kind = crate::source::classify(&path);
                if !file.is_empty() && kind == crate::source::FileKind::Regular {
                    image = Some((path, [scale; 3]));
                } else {
                    let why = match kind {
                        crate::source::FileKind::Other(what) => {
                            format!("{what}, not a regular file")
                        }
                        _ => "texture file missing".to_string(),
                    };
                    self.warn_once(
                        &format!("img:{file}"),
                        Some(tok.loc),
                        format!(
                            "texture \"{name}\" ({file}): {why}; the material's constant colour is used"
                        ),
                    );
                }
                [0.5; 3]
            }
            "ptex" => {
                // Read at import (motu-texture's Ptex reader), which warns about a missing
                // or corrupt file; a float (coverage) Ptex texture is not sampled.
                let file = p.string("filename").unwrap_or("").to_owned();
                if is_float {
                    self.warn_once(
                        "ptex-float",
                        Some(tok.loc),
                        format!(
                            "texture \"{name}\" ({file}): float ptex textures are not sampled; the constant is used"
                        ),
                    );
                }
                if !file.is_empty() && !is_float {
                    ptex = Some(self.resolve(&file));
                }
                [0.5; 3]
            }
            "scale" => {
                let (ka, kb) = if p.get("tex").is_some() || self.v4() {
                    ("tex", "scale")
                } else {
                    ("tex1", "tex2")
                };
                let (a, b) = (operand(self, ka, 1.0), operand(self, kb, 1.0));
                image = match (image_of(self, ka), image_of(self, kb)) {
                    (Some((path, f)), _) => Some((path, mul(f, b))),
                    (None, Some((path, f))) => Some((path, mul(f, a))),
                    (None, None) => None,
                };
                mul(a, b)
            }
            "mix" | "directionmix" => {
                let (a, b) = (operand(self, "tex1", 0.0), operand(self, "tex2", 1.0));
                let amount = p.get("amount").and_then(|x| self.color_of(x)).map(|t| t.0);
                // An image operand: the dominant side's image (amount < 0.5: tex1).
                let t = amount.map_or(0.5, |t| (t[0] + t[1] + t[2]) / 3.0);
                let (first, second) = (image_of(self, "tex1"), image_of(self, "tex2"));
                image = if t < 0.5 {
                    first.or(second)
                } else {
                    second.or(first)
                };
                match amount {
                    Some(t) => std::array::from_fn(|i| a[i] * (1.0 - t[i]) + b[i] * t[i]),
                    None => avg(a, b),
                }
            }
            "checkerboard" => avg(operand(self, "tex1", 1.0), operand(self, "tex2", 0.0)),
            "dots" => avg(operand(self, "inside", 1.0), operand(self, "outside", 0.0)),
            "bilerp" => {
                let (a, b) = (operand(self, "v00", 0.0), operand(self, "v01", 1.0));
                let (c, d) = (operand(self, "v10", 0.0), operand(self, "v11", 1.0));
                avg(avg(a, b), avg(c, d))
            }
            _ => [0.5; 3],
        };
        match ptex {
            Some(path) => {
                self.ptex_textures.insert(name.to_string(), path);
            }
            None if !is_float => {
                self.ptex_textures.remove(name.as_ref());
            }
            None => {}
        }
        match image {
            Some(img) => {
                self.image_textures
                    .insert((is_float, name.to_string()), img);
            }
            None => {
                self.image_textures.remove(&(is_float, name.to_string()));
            }
        }
        let table = if is_float {
            &mut self.float_textures
        } else {
            &mut self.color_textures
        };
        let redefined = table.insert(name.to_string(), value).is_some();
        if redefined {
            if self.v4() {
                return Err(self.err(
                    &ntok,
                    ParseErrorKind::Invalid("named texture redefined".into()),
                ));
            }
            // v3 scenes (Moana) redefine textures; the later definition wins.
            self.warn_once(
                &format!("texredef:{name}"),
                Some(ntok.loc),
                format!("texture \"{name}\" redefined"),
            );
        }
        Ok(())
    }

    // ---- shapes and objects ---------------------------------------------------------------
}
