//! `gast`: the GAST Studio command line and the studio itself. With no
//! arguments it opens the studio on the demo scene and style.

mod cli;
mod studio;

fn main() -> anyhow::Result<()> {
    cli::run()
}
