//! [`fes_figure::TAB10`] is matplotlib's tab10, colour for colour.

use plotters::style::RGBColor;

#[test]
fn tab10_is_matplotlibs() {
    // matplotlib.colors.TABLEAU_COLORS, in its order.
    let hex = [
        "1f77b4", "ff7f0e", "2ca02c", "d62728", "9467bd", "8c564b", "e377c2", "7f7f7f", "bcbd22",
        "17becf",
    ];
    let want: Vec<RGBColor> = hex
        .iter()
        .map(|h| {
            let c = |i: usize| u8::from_str_radix(&h[i..i + 2], 16).unwrap();
            RGBColor(c(0), c(2), c(4))
        })
        .collect();
    assert_eq!(fes_figure::TAB10.to_vec(), want);
}
