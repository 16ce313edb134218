//! A report: sections of text, tables and figures, written as `report.md` and `report.html`
//! (SVGs inlined) plus every table as CSV / Markdown / LaTeX and every figure as SVG / PNG.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::error::AnalysisError;
use crate::plots::Figure;
use crate::tables::{Table, html_escape};

/// The HTML report's layout width, CSS pixels (its body's `max-width`, the 60 em it always
/// had): a figure is shown this wide, its 650 viewBox units scaled up, so that its tick
/// labels (9 layout units, which the SVG writes as a font size of 9 / 1.24 = 7.26 units)
/// read at 7.26 × 960 / 650 ≈ 10.7 px, and no text of a figure is under 10 px.
pub const HTML_WIDTH_PX: u32 = 960;

/// The narrowest a figure is shown in the HTML report, CSS pixels (a narrower window scrolls
/// it): tick labels stay at 7.26 × 900 / 650 ≈ 10.05 px, never the 5-7 px of a figure
/// shrunk below its natural 650 px.
pub const HTML_FIGURE_MIN_PX: u32 = 900;

/// One element of a section.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum Block {
    /// A paragraph of plain text.
    Text(String),
    /// A table.
    Table(Table),
    /// A figure, written as `figures/<name>.svg` and `.png`.
    Figure {
        /// File stem.
        name: String,
        /// The figure.
        figure: Figure,
    },
}

/// A titled section.
#[derive(Debug, Clone, PartialEq)]
pub struct Section {
    /// Heading.
    pub heading: String,
    /// Contents in order.
    pub blocks: Vec<Block>,
}

impl Section {
    /// Appends a paragraph.
    pub fn text(&mut self, text: impl Into<String>) -> &mut Self {
        self.blocks.push(Block::Text(text.into()));
        self
    }

    /// Appends a table.
    pub fn table(&mut self, table: Table) -> &mut Self {
        self.blocks.push(Block::Table(table));
        self
    }

    /// Appends a figure.
    pub fn figure(&mut self, name: impl Into<String>, figure: Figure) -> &mut Self {
        self.blocks.push(Block::Figure {
            name: name.into(),
            figure,
        });
        self
    }
}

/// A whole report.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// Title (first heading).
    pub title: String,
    /// Sections in order.
    pub sections: Vec<Section>,
}

/// What [`Report::write`] produced.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct WrittenFiles {
    /// Every file written, in order.
    pub files: Vec<PathBuf>,
}

impl Report {
    /// An empty report.
    pub fn new(title: impl Into<String>) -> Self {
        Self {
            title: title.into(),
            sections: Vec::new(),
        }
    }

    /// Starts a new section and returns it for filling.
    pub fn section(&mut self, heading: impl Into<String>) -> &mut Section {
        self.sections.push(Section {
            heading: heading.into(),
            blocks: Vec::new(),
        });
        let last = self.sections.len() - 1;
        &mut self.sections[last]
    }

    /// Starts a new section before every other one (the method comes before the results).
    pub fn section_first(&mut self, heading: impl Into<String>) -> &mut Section {
        self.sections.insert(
            0,
            Section {
                heading: heading.into(),
                blocks: Vec::new(),
            },
        );
        &mut self.sections[0]
    }

    /// Every table in the report.
    pub fn tables(&self) -> impl Iterator<Item = &Table> {
        self.sections
            .iter()
            .flat_map(|s| s.blocks.iter())
            .filter_map(|b| match b {
                Block::Table(t) => Some(t),
                _ => None,
            })
    }

    /// Writes `report.md`, `report.html`, `tables/*.{csv,md,tex}` and `figures/*.{svg,png}`
    /// into `dir` (created if missing). With `png` false only SVGs are drawn. Each file is
    /// written whole or not at all ([`files::write`]); an existing file is replaced only with
    /// [`files::Mode::Replace`]. The pages come last, so a `report.md` is there only when every
    /// table and figure it shows is.
    ///
    /// # Errors
    /// [`AnalysisError::File`] naming the file that could not be written or exists;
    /// [`AnalysisError::Io`] for a folder that cannot be created; [`AnalysisError::Plot`] when
    /// a figure fails to draw.
    pub fn write(
        &self,
        dir: &Path,
        png: bool,
        mode: files::Mode,
    ) -> Result<WrittenFiles, AnalysisError> {
        let tables_dir = dir.join("tables");
        let figures_dir = dir.join("figures");
        for d in [dir, &tables_dir, &figures_dir] {
            std::fs::create_dir_all(d).map_err(|e| AnalysisError::io(d, e))?;
        }
        let mut written = WrittenFiles::default();
        let put = |written: &mut Vec<PathBuf>,
                   path: PathBuf,
                   bytes: &[u8]|
         -> Result<(), AnalysisError> {
            files::write(&path, bytes, mode)?;
            written.push(path);
            Ok(())
        };
        let mut md = format!("# {}\n\n", self.title);
        let mut html = format!(
            "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>{0}</title>\n<style>body{{font-family:sans-serif;max-width:{HTML_WIDTH_PX}px;margin:auto}}table{{border-collapse:collapse;margin:1em 0}}td,th{{border:1px solid #aaa;padding:2px 6px;text-align:right}}caption{{font-weight:bold}}figure{{margin:1em 0}}figure svg{{display:block;width:100%;min-width:{HTML_FIGURE_MIN_PX}px;height:auto}}</style></head><body>\n<h1>{0}</h1>\n",
            html_escape(&self.title)
        );
        for section in &self.sections {
            let _ = write!(md, "## {}\n\n", section.heading);
            let _ = writeln!(html, "<h2>{}</h2>", html_escape(&section.heading));
            for block in &section.blocks {
                match block {
                    Block::Text(t) => {
                        let _ = write!(md, "{t}\n\n");
                        let _ = writeln!(html, "<p>{}</p>", html_escape(t));
                    }
                    Block::Table(t) => {
                        put(
                            &mut written.files,
                            tables_dir.join(format!("{}.csv", t.name)),
                            t.to_csv().as_bytes(),
                        )?;
                        let markdown = t.to_markdown();
                        put(
                            &mut written.files,
                            tables_dir.join(format!("{}.md", t.name)),
                            markdown.as_bytes(),
                        )?;
                        put(
                            &mut written.files,
                            tables_dir.join(format!("{}.tex", t.name)),
                            t.to_latex().as_bytes(),
                        )?;
                        md.push_str(&markdown);
                        md.push('\n');
                        html.push_str(&t.to_html());
                    }
                    Block::Figure { name, figure } => {
                        let svg = figure.render_svg()?;
                        put(
                            &mut written.files,
                            figures_dir.join(format!("{name}.svg")),
                            svg.as_bytes(),
                        )?;
                        if png {
                            put(
                                &mut written.files,
                                figures_dir.join(format!("{name}.png")),
                                &figure.render_png()?,
                            )?;
                        }
                        let _ = write!(md, "![{}](figures/{name}.svg)\n\n", figure.title());
                        let body = svg.trim_start_matches(|c| c != '<');
                        let body = if body.starts_with("<?xml") {
                            body.split_once("?>").map_or(body, |(_, rest)| rest)
                        } else {
                            body
                        };
                        let _ = writeln!(
                            html,
                            "<figure>{body}<figcaption>{}</figcaption></figure>",
                            html_escape(figure.title())
                        );
                    }
                }
            }
        }
        html.push_str("</body></html>\n");
        put(&mut written.files, dir.join("report.md"), md.as_bytes())?;
        put(&mut written.files, dir.join("report.html"), html.as_bytes())?;
        Ok(written)
    }
}
