//! docs/options.md, the options reference, is what the command line says about itself: the
//! checked-in page equals the generator's output, and each of its sections equals what the
//! real binary prints for `--help`.

mod common;
use common::*;
use icrender::commands::help_reference;

fn page() -> String {
    std::fs::read_to_string(project_dir().join("docs/options.md")).expect("docs/options.md exists")
}

#[test]
fn the_checked_in_options_reference_is_up_to_date() {
    let made = help_reference::markdown();
    if page() != made {
        let first = page()
            .lines()
            .zip(made.lines())
            .position(|(a, b)| a != b)
            .map_or("the length".to_string(), |n| format!("line {}", n + 1));
        panic!(
            "docs/options.md differs from the command-line definition (first at {first}); make it again with\n    {}",
            help_reference::REGENERATE
        );
    }
}

#[test]
fn every_section_is_what_help_prints() {
    let text = page();
    let mut sections = 0;
    for block in text.split("\n## `").skip(1) {
        let (title, rest) = block.split_once("`\n").unwrap();
        let words: Vec<&str> = title.split_whitespace().skip(1).collect();
        let body = rest
            .split_once("```text\n")
            .and_then(|(_, b)| b.split_once("\n```"))
            .map(|(b, _)| b)
            .unwrap_or_else(|| panic!("section {title} has no help block"));
        let mut args = words.clone();
        args.push("--help");
        let printed = stdout(&run_ok(&args));
        let printed = printed.trim_end();
        if body != printed {
            let (page_line, help_line) = body
                .lines()
                .zip(printed.lines())
                .find(|(a, b)| a != b)
                .unwrap_or(("(one ends here)", "(the other goes on)"));
            panic!(
                "docs/options.md's section `{title}` is not what `{title} --help` prints:\n  page: {page_line}\n  help: {help_line}\nmake the page again with\n    {}",
                help_reference::REGENERATE
            );
        }
        sections += 1;
    }
    // The top level, render, info, compare, seams, bench and its two, reference, export,
    // cache, merge.
    assert!(sections >= 12, "only {sections} sections in docs/options.md");
}
