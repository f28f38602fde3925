//! `gast`: the GAST Studio command line (and, later, the studio itself).

fn main() -> anyhow::Result<()> {
    Ok(())
}
