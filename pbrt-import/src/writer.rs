//! A small pbrt-v4 text writer (round-trip tests, fuzz seeds, test-scene generation).
//!
//! Floats are written with Rust's shortest round-trip formatting, so parsing the
//! output gives bit-identical `f32` values.

use std::fmt::Write as _;

use crate::events::Mesh;
use crate::math::Mat4;

/// Builds pbrt scene text directive by directive.
#[derive(Debug, Default)]
pub struct Writer {
    out: String,
    indent: usize,
}

fn nums(out: &mut String, v: impl IntoIterator<Item = f32>) {
    out.push('[');
    for x in v {
        let _ = write!(out, " {x}");
    }
    out.push_str(" ]");
}

fn quote(s: &str) -> String {
    let mut q = String::with_capacity(s.len() + 2);
    q.push('"');
    for c in s.chars() {
        match c {
            '"' => q.push_str("\\\""),
            '\\' => q.push_str("\\\\"),
            '\n' => q.push_str("\\n"),
            c => q.push(c),
        }
    }
    q.push('"');
    q
}

impl Writer {
    /// Empty document.
    pub fn new() -> Self {
        Self::default()
    }

    /// The text so far.
    pub fn finish(self) -> String {
        self.out
    }

    fn line(&mut self, s: &str) {
        for _ in 0..self.indent {
            self.out.push_str("    ");
        }
        self.out.push_str(s);
        self.out.push('\n');
    }

    /// A `#` comment.
    pub fn comment(&mut self, text: &str) {
        self.line(&format!("# {}", text.replace('\n', " ")));
    }

    /// `LookAt`.
    pub fn look_at(&mut self, eye: [f32; 3], look: [f32; 3], up: [f32; 3]) {
        let v: Vec<String> = eye
            .iter()
            .chain(&look)
            .chain(&up)
            .map(|x| x.to_string())
            .collect();
        self.line(&format!("LookAt {}", v.join(" ")));
    }

    /// `Camera "perspective" "float fov"`.
    pub fn perspective_camera(&mut self, fov_deg: f32) {
        self.line(&format!(
            "Camera \"perspective\" \"float fov\" [ {fov_deg} ]"
        ));
    }

    /// `Film "rgb"` with a resolution.
    pub fn film(&mut self, resolution: [u32; 2]) {
        self.line(&format!(
            "Film \"rgb\" \"integer xresolution\" [ {} ] \"integer yresolution\" [ {} ]",
            resolution[0], resolution[1]
        ));
    }

    /// `WorldBegin`.
    pub fn world_begin(&mut self) {
        self.line("WorldBegin");
    }

    /// `AttributeBegin` (indents).
    pub fn attribute_begin(&mut self) {
        self.line("AttributeBegin");
        self.indent += 1;
    }

    /// `AttributeEnd`.
    pub fn attribute_end(&mut self) {
        self.indent = self.indent.saturating_sub(1);
        self.line("AttributeEnd");
    }

    /// `Transform [16]` (pbrt's column-major order).
    pub fn transform(&mut self, m: &Mat4) {
        let mut s = String::from("Transform ");
        nums(&mut s, m.to_cols_array());
        self.line(&s);
    }

    /// `ConcatTransform [16]`.
    pub fn concat_transform(&mut self, m: &Mat4) {
        let mut s = String::from("ConcatTransform ");
        nums(&mut s, m.to_cols_array());
        self.line(&s);
    }

    /// `MakeNamedMaterial name "string type" "diffuse" "rgb reflectance" rgb`.
    pub fn named_diffuse(&mut self, name: &str, rgb: [f32; 3]) {
        let mut s = format!(
            "MakeNamedMaterial {} \"string type\" \"diffuse\" \"rgb reflectance\" ",
            quote(name)
        );
        nums(&mut s, rgb);
        self.line(&s);
    }

    /// `NamedMaterial`.
    pub fn named_material(&mut self, name: &str) {
        self.line(&format!("NamedMaterial {}", quote(name)));
    }

    /// `ObjectBegin` (indents).
    pub fn object_begin(&mut self, name: &str) {
        self.line(&format!("ObjectBegin {}", quote(name)));
        self.indent += 1;
    }

    /// `ObjectEnd`.
    pub fn object_end(&mut self) {
        self.indent = self.indent.saturating_sub(1);
        self.line("ObjectEnd");
    }

    /// `ObjectInstance`.
    pub fn object_instance(&mut self, name: &str) {
        self.line(&format!("ObjectInstance {}", quote(name)));
    }

    /// `Shape "trianglemesh"` with indices, P and optional N/uv.
    pub fn triangle_mesh(&mut self, mesh: &Mesh) {
        let mut s = String::from("Shape \"trianglemesh\"\n    \"integer indices\" [");
        for i in &mesh.indices {
            let _ = write!(s, " {i}");
        }
        s.push_str(" ]\n    \"point3 P\" ");
        nums(&mut s, mesh.positions.iter().flatten().copied());
        if let Some(n) = &mesh.normals {
            s.push_str("\n    \"normal N\" ");
            nums(&mut s, n.iter().flatten().copied());
        }
        if let Some(uv) = &mesh.uvs {
            s.push_str("\n    \"point2 uv\" ");
            nums(&mut s, uv.iter().flatten().copied());
        }
        self.line(&s);
    }

    /// `Shape "plymesh" "string filename"`.
    pub fn plymesh(&mut self, filename: &str) {
        self.line(&format!(
            "Shape \"plymesh\" \"string filename\" {}",
            quote(filename)
        ));
    }

    /// `Include`.
    pub fn include(&mut self, filename: &str) {
        self.line(&format!("Include {}", quote(filename)));
    }

    /// Any raw line.
    pub fn raw(&mut self, text: &str) {
        self.line(text);
    }
}
