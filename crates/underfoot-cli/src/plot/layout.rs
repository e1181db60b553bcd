//! The layout check: before a figure is written, it is drawn once more on a backend that
//! paints nothing and records where every text would go, and the boxes are checked.
//!
//! A text's box is the one the bitmap backend would fill: the font's layout box when a
//! font is loaded, else a generous 0.6 em a character by 1.2 em (what an SVG viewer's
//! sans-serif needs at most), moved by its anchor and turned by its rotation exactly as
//! plotters' own `draw_text` does. Two boxes overlap when they share more than
//! [`SLACK_PX`] pixels both ways: touching is fine (a glyph's box has its side bearings),
//! crossing is not. A box past the canvas's edge is clipped text. The figure also reports
//! its axes' ranges ([`Figure::axes`](super::Figure::axes)), and an empty or non-finite
//! range (a frame with nothing to show, a log axis from 0) is a problem too.
//!
//! The check runs on every figure the CLI writes, so a problem is reported where it
//! happens (a warning that names the figure and the texts) rather than found by eye.

use std::cell::RefCell;
use std::convert::Infallible;
use std::rc::Rc;

use plotters::prelude::*;
use plotters_backend::text_anchor::{HPos, VPos};
use plotters_backend::{
    BackendColor, BackendCoord, BackendStyle, BackendTextStyle, DrawingErrorKind,
};

use super::Figure;

/// How far two boxes may cross before it counts as an overlap, pixels.
const SLACK_PX: i32 = 1;

/// A text as it would be drawn: what it says and the box it fills, in pixels.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) struct TextBox {
    pub text: String,
    /// `(left, top)`, inclusive.
    pub min: (i32, i32),
    /// `(right, bottom)`, exclusive.
    pub max: (i32, i32),
}

impl TextBox {
    fn crosses(&self, other: &Self) -> bool {
        let across = self.max.0.min(other.max.0) - self.min.0.max(other.min.0);
        let down = self.max.1.min(other.max.1) - self.min.1.max(other.min.1);
        across > SLACK_PX && down > SLACK_PX
    }
}

/// One axis of a figure's frames: its name and the range it shows.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct AxisSpan {
    pub name: String,
    pub range: (f64, f64),
    pub log: bool,
}

impl AxisSpan {
    pub fn linear(name: impl Into<String>, range: (f64, f64)) -> Self {
        Self {
            name: name.into(),
            range,
            log: false,
        }
    }

    pub fn log(name: impl Into<String>, range: (f64, f64)) -> Self {
        Self {
            name: name.into(),
            range,
            log: true,
        }
    }
}

/// Where a figure's texts go, and the ranges of its axes.
#[derive(Debug, Clone)]
pub(super) struct Layout {
    pub size: (u32, u32),
    pub texts: Vec<TextBox>,
    pub axes: Vec<AxisSpan>,
}

impl Layout {
    /// Lays `figure` out on a canvas of `size` pixels.
    pub fn of(figure: &impl Figure, size: (u32, u32)) -> Self {
        let texts = Rc::new(RefCell::new(Vec::new()));
        let root = Recorder {
            size,
            texts: Rc::clone(&texts),
        }
        .into_drawing_area();
        // The recorder cannot fail; a figure that cannot draw fails again, with its own
        // message, when it is drawn for real.
        let _ = figure.draw_on(&root);
        drop(root);
        Self {
            size,
            texts: texts.take(),
            axes: figure.axes(),
        }
    }

    /// What is wrong with the layout, one sentence each; empty when nothing is.
    pub fn problems(&self) -> Vec<String> {
        let mut problems = Vec::new();
        let (w, h) = (self.size.0 as i32, self.size.1 as i32);
        for (i, a) in self.texts.iter().enumerate() {
            for b in &self.texts[i + 1..] {
                if a.crosses(b) {
                    problems.push(format!("text \"{}\" overlaps \"{}\"", a.text, b.text));
                }
            }
            if a.min.0 < -SLACK_PX
                || a.min.1 < -SLACK_PX
                || a.max.0 > w + SLACK_PX
                || a.max.1 > h + SLACK_PX
            {
                problems.push(format!("text \"{}\" runs past the figure's edge", a.text));
            }
        }
        for axis in &self.axes {
            let (lo, hi) = axis.range;
            if !(lo.is_finite() && hi.is_finite() && lo < hi) || (axis.log && lo <= 0.0) {
                problems.push(format!(
                    "the {} axis has an empty range ({lo} to {hi})",
                    axis.name
                ));
            }
        }
        problems
    }
}

/// A backend that draws nothing and records texts' boxes (shared, because a drawing
/// area owns its backend).
struct Recorder {
    size: (u32, u32),
    texts: Rc<RefCell<Vec<TextBox>>>,
}

impl DrawingBackend for Recorder {
    type ErrorType = Infallible;

    fn get_size(&self) -> (u32, u32) {
        self.size
    }

    fn ensure_prepared(&mut self) -> Result<(), DrawingErrorKind<Infallible>> {
        Ok(())
    }

    fn present(&mut self) -> Result<(), DrawingErrorKind<Infallible>> {
        Ok(())
    }

    fn draw_pixel(
        &mut self,
        _: BackendCoord,
        _: BackendColor,
    ) -> Result<(), DrawingErrorKind<Infallible>> {
        Ok(())
    }

    // Lines, rectangles and polygons are not text: skipping them keeps the layout pass
    // cheap (the default implementations would walk every pixel of every curve).
    fn draw_line<S: BackendStyle>(
        &mut self,
        _: BackendCoord,
        _: BackendCoord,
        _: &S,
    ) -> Result<(), DrawingErrorKind<Infallible>> {
        Ok(())
    }

    fn draw_rect<S: BackendStyle>(
        &mut self,
        _: BackendCoord,
        _: BackendCoord,
        _: &S,
        _: bool,
    ) -> Result<(), DrawingErrorKind<Infallible>> {
        Ok(())
    }

    fn draw_path<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        _: I,
        _: &S,
    ) -> Result<(), DrawingErrorKind<Infallible>> {
        Ok(())
    }

    fn draw_circle<S: BackendStyle>(
        &mut self,
        _: BackendCoord,
        _: u32,
        _: &S,
        _: bool,
    ) -> Result<(), DrawingErrorKind<Infallible>> {
        Ok(())
    }

    fn fill_polygon<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        _: I,
        _: &S,
    ) -> Result<(), DrawingErrorKind<Infallible>> {
        Ok(())
    }

    fn blit_bitmap(
        &mut self,
        _: BackendCoord,
        _: (u32, u32),
        _: &[u8],
    ) -> Result<(), DrawingErrorKind<Infallible>> {
        Ok(())
    }

    fn draw_text<T: BackendTextStyle>(
        &mut self,
        text: &str,
        style: &T,
        pos: BackendCoord,
    ) -> Result<(), DrawingErrorKind<Infallible>> {
        // Transparent text is not drawn (a PNG without a font); blank labels (a log
        // axis's unlabelled grid lines) take no room.
        if style.color().alpha == 0.0 || text.trim().is_empty() {
            return Ok(());
        }
        let (width, height) = measure(text, style);
        let dx = match style.anchor().h_pos {
            HPos::Left => 0,
            HPos::Right => -width,
            HPos::Center => -width / 2,
        };
        let dy = match style.anchor().v_pos {
            VPos::Top => 0,
            VPos::Center => -height / 2,
            VPos::Bottom => -height,
        };
        let turn = style.transform();
        let (ax, ay) = turn.transform(dx, dy);
        let (bx, by) = turn.transform(dx + width, dy + height);
        self.texts.borrow_mut().push(TextBox {
            text: text.to_owned(),
            min: (pos.0 + ax.min(bx), pos.1 + ay.min(by)),
            max: (pos.0 + ax.max(bx), pos.1 + ay.max(by)),
        });
        Ok(())
    }

    fn estimate_text_size<T: BackendTextStyle>(
        &self,
        text: &str,
        style: &T,
    ) -> Result<(u32, u32), DrawingErrorKind<Infallible>> {
        let (w, h) = measure(text, style);
        Ok((w.unsigned_abs(), h.unsigned_abs()))
    }
}

/// A text's unturned width and height: the font's layout box, else 0.6 em a character
/// by 1.2 em.
fn measure<T: BackendTextStyle>(text: &str, style: &T) -> (i32, i32) {
    match style.layout_box(text) {
        Ok(((x0, y0), (x1, y1))) => (x1 - x0, y1 - y0),
        Err(_) => {
            let em = style.size();
            (
                (0.6 * em * text.chars().count() as f64).ceil() as i32,
                (1.2 * em).ceil() as i32,
            )
        }
    }
}

#[cfg(test)]
mod tests {
    use plotters::style::text_anchor::Pos;

    use plotters::coord::Shift;

    use super::*;
    use crate::plot::font::FAMILY;

    /// A figure of texts placed by hand, and one axis.
    struct Texts(
        Vec<(&'static str, (i32, i32), Pos, FontTransform)>,
        AxisSpan,
    );

    impl Figure for Texts {
        fn draw_on<DB: DrawingBackend>(
            &self,
            root: &DrawingArea<DB, Shift>,
        ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
            for (t, at, pos, turn) in &self.0 {
                let style = (FAMILY, 20.0)
                    .into_font()
                    .transform(turn.clone())
                    .color(&BLACK)
                    .pos(*pos);
                root.draw(&Text::new(*t, *at, style))?;
            }
            Ok(())
        }

        fn axes(&self) -> Vec<AxisSpan> {
            vec![self.1.clone()]
        }
    }

    fn left() -> Pos {
        Pos::new(HPos::Left, VPos::Top)
    }

    #[test]
    fn crossing_texts_clipped_texts_and_empty_axes_are_found() {
        let fine = Texts(
            vec![
                ("one", (10, 10), left(), FontTransform::None),
                ("two", (10, 60), left(), FontTransform::None),
            ],
            AxisSpan::log("frequency", (20.0, 900.0)),
        );
        assert_eq!(
            Layout::of(&fine, (300, 200)).problems(),
            Vec::<String>::new()
        );

        let crossing = Texts(
            vec![
                ("a long title", (10, 10), left(), FontTransform::None),
                ("legend", (40, 14), left(), FontTransform::None),
                ("clipped", (280, 10), left(), FontTransform::None),
            ],
            AxisSpan::log("frequency", (0.0, 900.0)),
        );
        let problems = Layout::of(&crossing, (300, 200)).problems();
        assert_eq!(problems.len(), 3, "{problems:?}");
        assert!(problems[0].contains("\"a long title\" overlaps \"legend\""));
        assert!(problems[1].contains("\"clipped\" runs past"));
        assert!(problems[2].contains("frequency axis has an empty range"));
    }

    #[test]
    fn a_turned_text_is_tall_not_wide() {
        // A y-axis name turned a quarter, centred at x = 20: it must not reach a label
        // 40 px to its right, which it would if its box were not turned.
        let turned = Texts(
            vec![
                (
                    "magnitude (dB)",
                    (20, 100),
                    Pos::new(HPos::Center, VPos::Center),
                    FontTransform::Rotate270,
                ),
                ("-20", (45, 95), left(), FontTransform::None),
            ],
            AxisSpan::linear("magnitude", (-40.0, 0.0)),
        );
        let layout = Layout::of(&turned, (300, 200));
        let name = &layout.texts[0];
        assert!(
            name.max.1 - name.min.1 > 3 * (name.max.0 - name.min.0),
            "{name:?}"
        );
        assert_eq!(layout.problems(), Vec::<String>::new());
    }
}
