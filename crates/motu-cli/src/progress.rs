//! Progress bars on a terminal, silence otherwise (the CLI contract).

use indicatif::{ProgressBar, ProgressStyle};
use std::io::IsTerminal;

#[derive(Clone)]
pub struct Progress {
    bar: Option<ProgressBar>,
}

impl Progress {
    /// A byte-counting bar, shown only when stderr is a terminal.
    pub fn bytes(label: &str) -> Self {
        Self::with_template(
            label,
            "{msg} {bytes} {binary_bytes_per_sec} [{elapsed_precise}]",
        )
    }

    /// A bar of bytes done out of a known (estimated) total.
    pub fn bytes_of_total(label: &str) -> Self {
        Self::with_template(
            label,
            "{msg} [{bar:30}] {bytes}/{total_bytes} {binary_bytes_per_sec} eta {eta}",
        )
    }

    fn with_template(label: &str, template: &str) -> Self {
        if !std::io::stderr().is_terminal() {
            return Self { bar: None };
        }
        let bar = ProgressBar::new(0);
        bar.set_style(
            ProgressStyle::with_template(template).unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        bar.set_message(label.to_string());
        Self { bar: Some(bar) }
    }

    pub fn set(&self, done: u64, total: Option<u64>) {
        if let Some(b) = &self.bar {
            if let Some(t) = total {
                b.set_length(t);
            }
            b.set_position(done);
        }
    }

    pub fn finish(&self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }
}

/// The import's parse bar (bytes parsed out of the scene text's size), cleared when parsing
/// ends; `None` when stderr is no terminal.
pub fn import_bar() -> Option<motu_import::ProgressFn> {
    let bar = Progress::bytes_of_total("parsing pbrt");
    bar.bar.as_ref()?;
    Some(std::sync::Arc::new(move |p| match p {
        motu_import::ImportProgress::Parsing { bytes, total_bytes } => {
            bar.set(bytes, Some(total_bytes))
        }
        motu_import::ImportProgress::Parsed => bar.finish(),
    }))
}
