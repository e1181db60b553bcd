//! A figure drawn larger than it is laid out: `--plot-scale K`.
//!
//! Every figure is laid out in pixels of its base size (a 720x420 panel): margins, label
//! areas, legend rows and text sizes are constants of that size, and the layout check
//! ([`super::layout`]) runs on it. [`Scaled`] shows the figure a backend of the base
//! size and draws each primitive on the real backend `K` times larger: coordinates,
//! stroke widths, circle radii and font sizes times `K`, so the picture is the base one,
//! sharper, rather than the base one with more room around small text. Text is drawn by
//! the real backend at `K` times its size (glyphs rasterised at the final resolution,
//! never an enlarged bitmap); a bitmap (the spectrogram's cells) is enlarged by
//! repeating pixels, which is what its cells are.
//!
//! Points are placed on the base layout's integer grid, so a curve's vertices may sit up
//! to `K/2` pixels from where a layout made at the larger size would put them: at
//! `K = 2.5` that is 1.25 px under a 5-px line.

use plotters::style::{FontDesc, TextStyle};
use plotters_backend::{
    BackendColor, BackendCoord, BackendStyle, BackendTextStyle, DrawingBackend, DrawingErrorKind,
};

use super::Scale;

/// A backend of the base size drawing on `inner`, `scale` times larger.
pub(super) struct Scaled<B> {
    inner: B,
    base: (u32, u32),
    k: f64,
}

impl<B: DrawingBackend> Scaled<B> {
    pub fn new(inner: B, base: (u32, u32), scale: Scale) -> Self {
        Self {
            inner,
            base,
            k: scale.get(),
        }
    }

    fn at(&self, (x, y): BackendCoord) -> BackendCoord {
        (
            (f64::from(x) * self.k).round() as i32,
            (f64::from(y) * self.k).round() as i32,
        )
    }

    fn length(&self, v: u32) -> u32 {
        (f64::from(v) * self.k).round().max(1.0) as u32
    }
}

/// A style whose stroke is `k` times as wide.
struct Wider<'a, S> {
    style: &'a S,
    width: u32,
}

impl<S: BackendStyle> BackendStyle for Wider<'_, S> {
    fn color(&self) -> BackendColor {
        self.style.color()
    }

    fn stroke_width(&self) -> u32 {
        self.width
    }
}

impl<B: DrawingBackend> Scaled<B> {
    fn wider<'a, S: BackendStyle>(&self, style: &'a S) -> Wider<'a, S> {
        Wider {
            style,
            width: self.length(style.stroke_width()),
        }
    }

    /// The same text style, `k` times the size.
    fn larger<'a, T: BackendTextStyle>(&self, style: &'a T) -> TextStyle<'a> {
        TextStyle {
            font: FontDesc::new(style.family(), style.size() * self.k, style.style())
                .transform(style.transform()),
            color: style.color(),
            pos: style.anchor(),
        }
    }
}

impl<B: DrawingBackend> DrawingBackend for Scaled<B> {
    type ErrorType = B::ErrorType;

    fn get_size(&self) -> (u32, u32) {
        self.base
    }

    fn ensure_prepared(&mut self) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.ensure_prepared()
    }

    fn present(&mut self) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.present()
    }

    fn draw_pixel(
        &mut self,
        point: BackendCoord,
        color: BackendColor,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        let from = self.at(point);
        let to = self.at((point.0 + 1, point.1 + 1));
        self.inner
            .draw_rect(from, (to.0 - 1, to.1 - 1), &color, true)
    }

    fn draw_line<S: BackendStyle>(
        &mut self,
        from: BackendCoord,
        to: BackendCoord,
        style: &S,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        let (from, to, style) = (self.at(from), self.at(to), self.wider(style));
        self.inner.draw_line(from, to, &style)
    }

    fn draw_rect<S: BackendStyle>(
        &mut self,
        upper_left: BackendCoord,
        bottom_right: BackendCoord,
        style: &S,
        fill: bool,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        let (a, b, style) = (
            self.at(upper_left),
            self.at(bottom_right),
            self.wider(style),
        );
        self.inner.draw_rect(a, b, &style, fill)
    }

    fn draw_path<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        path: I,
        style: &S,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        let points: Vec<BackendCoord> = path.into_iter().map(|p| self.at(p)).collect();
        let style = self.wider(style);
        self.inner.draw_path(points, &style)
    }

    fn draw_circle<S: BackendStyle>(
        &mut self,
        center: BackendCoord,
        radius: u32,
        style: &S,
        fill: bool,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        let (center, radius, style) = (self.at(center), self.length(radius), self.wider(style));
        self.inner.draw_circle(center, radius, &style, fill)
    }

    fn fill_polygon<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        vert: I,
        style: &S,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        let points: Vec<BackendCoord> = vert.into_iter().map(|p| self.at(p)).collect();
        self.inner.fill_polygon(points, style)
    }

    fn draw_text<T: BackendTextStyle>(
        &mut self,
        text: &str,
        style: &T,
        pos: BackendCoord,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        let (pos, style) = (self.at(pos), self.larger(style));
        self.inner.draw_text(text, &style, pos)
    }

    fn estimate_text_size<T: BackendTextStyle>(
        &self,
        text: &str,
        style: &T,
    ) -> Result<(u32, u32), DrawingErrorKind<B::ErrorType>> {
        let (w, h) = self.inner.estimate_text_size(text, &self.larger(style))?;
        let back = |v: u32| (f64::from(v) / self.k).round() as u32;
        Ok((back(w), back(h)))
    }

    fn blit_bitmap(
        &mut self,
        pos: BackendCoord,
        (w, h): (u32, u32),
        src: &[u8],
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        let from = self.at(pos);
        let to = self.at((pos.0 + w as i32, pos.1 + h as i32));
        let (sw, sh) = ((to.0 - from.0).max(1) as u32, (to.1 - from.1).max(1) as u32);
        // Each target pixel takes the source pixel under its centre.
        let mut out = Vec::with_capacity(3 * sw as usize * sh as usize);
        for j in 0..sh {
            let sy = ((f64::from(j) + 0.5) / self.k) as u32;
            let row = sy.min(h - 1) as usize * w as usize;
            for i in 0..sw {
                let sx = ((f64::from(i) + 0.5) / self.k) as u32;
                let at = 3 * (row + sx.min(w - 1) as usize);
                out.extend_from_slice(&src[at..at + 3]);
            }
        }
        self.inner.blit_bitmap(from, (sw, sh), &out)
    }
}

#[cfg(test)]
mod tests {
    use plotters::prelude::*;

    use super::*;

    /// A red square 10 px from the corner, 20 px wide, with a 2-px black line across.
    fn picture<DB: DrawingBackend>(area: &DrawingArea<DB, plotters::coord::Shift>) {
        area.fill(&WHITE).unwrap();
        area.draw(&Rectangle::new([(10, 10), (30, 30)], RED.filled()))
            .unwrap();
        area.draw(&PathElement::new(
            vec![(0, 50), (60, 50)],
            Color::stroke_width(&BLACK, 2),
        ))
        .unwrap();
    }

    #[test]
    fn a_scaled_picture_is_the_picture_larger() {
        let (base, k) = ((60_u32, 60_u32), 3.0);
        let big = (180_u32, 180_u32);
        let mut rgb = vec![0_u8; 3 * 180 * 180];
        {
            let scaled = Scaled::new(
                BitMapBackend::with_buffer(&mut rgb, big),
                base,
                Scale::new(k).unwrap(),
            );
            let area = scaled.into_drawing_area();
            assert_eq!(area.dim_in_pixel(), base, "the figure sees its base size");
            picture(&area);
            area.present().unwrap();
        }
        let pixel = |x: usize, y: usize| &rgb[3 * (y * 180 + x)..3 * (y * 180 + x) + 3];
        // The square spans 30..=90 now; its inside is red, just outside is white.
        assert_eq!(pixel(60, 60), [255, 0, 0]);
        assert_eq!(pixel(31, 31), [255, 0, 0]);
        assert_eq!(pixel(26, 60), [255, 255, 255]);
        assert_eq!(pixel(95, 60), [255, 255, 255]);
        // The line at y = 150 is 6 px thick: black at 148..=152, white at 145 and 155.
        let black = (140..160).filter(|&y| pixel(90, y) == [0, 0, 0]).count();
        assert!((5..=7).contains(&black), "{black} px thick");
        assert_eq!(pixel(90, 150), [0, 0, 0]);
    }

    #[test]
    fn a_bitmap_is_enlarged_pixel_for_pixel() {
        let mut rgb = vec![0_u8; 3 * 8 * 8];
        {
            let mut scaled = Scaled::new(
                BitMapBackend::with_buffer(&mut rgb, (8, 8)),
                (4, 4),
                Scale::new(2.0).unwrap(),
            );
            // A 2x2 checkerboard of red and blue at (1, 1).
            let src = [255, 0, 0, 0, 0, 255, 0, 0, 255, 255, 0, 0];
            scaled.blit_bitmap((1, 1), (2, 2), &src).unwrap();
            scaled.present().unwrap();
        }
        let pixel = |x: usize, y: usize| &rgb[3 * (y * 8 + x)..3 * (y * 8 + x) + 3];
        assert_eq!(pixel(2, 2), [255, 0, 0]);
        assert_eq!(pixel(3, 3), [255, 0, 0]);
        assert_eq!(pixel(4, 2), [0, 0, 255]);
        assert_eq!(pixel(2, 5), [0, 0, 255]);
        assert_eq!(pixel(5, 5), [255, 0, 0]);
        assert_eq!(pixel(0, 0), [0, 0, 0], "outside the bitmap: untouched");
    }

    #[test]
    fn scales_out_of_range_are_refused() {
        assert!(Scale::new(2.5).is_ok());
        for bad in [0.0, -1.0, 0.1, 9.0, f64::NAN, f64::INFINITY] {
            assert!(Scale::new(bad).is_err(), "{bad}");
        }
        assert!("2,5".parse::<Scale>().unwrap_err().contains("such as 2.5"));
    }
}
