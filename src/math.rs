//! Transcendental functions from the pure-Rust `libm` on every platform, so a fit gives
//! the same bits natively and in wasm (std's `sin`, `exp`, … call the platform's math
//! library natively and a port of musl's in wasm, which differ in the last bit for some
//! inputs). Called as `x.lsin()` etc. (std's inherent methods cannot be overridden).

pub trait Libm: Sized {
    fn lsin(self) -> Self;
    fn lcos(self) -> Self;
    fn lsin_cos(self) -> (Self, Self);
    fn ltan(self) -> Self;
    fn lasin(self) -> Self;
    fn lacos(self) -> Self;
    fn latan(self) -> Self;
    fn latan2(self, x: Self) -> Self;
    fn lexp(self) -> Self;
    fn lln(self) -> Self;
    fn lcbrt(self) -> Self;
}

macro_rules! libm_impl {
    ($t:ty, $sin:ident, $cos:ident, $tan:ident, $asin:ident, $acos:ident, $atan:ident, $atan2:ident, $exp:ident, $ln:ident, $cbrt:ident) => {
        impl Libm for $t {
            #[inline]
            fn lsin(self) -> Self {
                libm::$sin(self)
            }
            #[inline]
            fn lcos(self) -> Self {
                libm::$cos(self)
            }
            #[inline]
            fn lsin_cos(self) -> (Self, Self) {
                (libm::$sin(self), libm::$cos(self))
            }
            #[inline]
            fn ltan(self) -> Self {
                libm::$tan(self)
            }
            #[inline]
            fn lasin(self) -> Self {
                libm::$asin(self)
            }
            #[inline]
            fn lacos(self) -> Self {
                libm::$acos(self)
            }
            #[inline]
            fn latan(self) -> Self {
                libm::$atan(self)
            }
            #[inline]
            fn latan2(self, x: Self) -> Self {
                libm::$atan2(self, x)
            }
            #[inline]
            fn lexp(self) -> Self {
                libm::$exp(self)
            }
            #[inline]
            fn lln(self) -> Self {
                libm::$ln(self)
            }
            #[inline]
            fn lcbrt(self) -> Self {
                libm::$cbrt(self)
            }
        }
    };
}
libm_impl!(f64, sin, cos, tan, asin, acos, atan, atan2, exp, log, cbrt);
libm_impl!(f32, sinf, cosf, tanf, asinf, acosf, atanf, atan2f, expf, logf, cbrtf);
