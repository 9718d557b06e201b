//! What the console shows, as plain data ([`Screen`]), and how it is drawn ([`draw`]): pure,
//! the layout taken from the frame's size only, so that unit tests draw into ratatui's
//! `TestBackend` at any size and read the text back. Gathering the data is `live`'s.

use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Borders, Cell, Paragraph, Row, Table, Wrap};
use ratatui::Frame;
use teleop_msgs::{GLOVE_CHANNELS, GLOVE_FINGERS};

use super::keys::Prompt;
use crate::inspect::TopicSummary;

/// Full scale of a tactile bar, N (a larger force shows a full bar and its number).
pub const TACTILE_FULL_SCALE_N: f32 = 10.0;
/// Full scale of a glove force bar, glove units (the contract's range is -1000..1000).
pub const GLOVE_FORCE_FULL_SCALE: f32 = 1000.0;

/// Everything the console shows at one refresh.
#[derive(Debug, Clone, Default)]
pub struct Screen {
    /// The sides looked at (`(none)` for the topics without a namespace).
    pub sides: Vec<String>,
    /// Seconds the topic rates and latencies are measured over.
    pub window_s: f64,
    pub estop: EStopView,
    /// The session's nodes, by name.
    pub nodes: Vec<NodeLine>,
    /// The topics that had samples (or drops) in the window.
    pub topics: Vec<TopicSummary>,
    /// Per side with a glove or a hand: its bars.
    pub hands: Vec<HandView>,
    /// The links between stations (bridges' health).
    pub links: Vec<LinkView>,
    /// The recorders' state (their health).
    pub recorders: Vec<RecorderView>,
    /// What the last action (e-stop, episode) did.
    pub message: String,
    /// The prompt open, if any.
    pub prompt: Prompt,
    /// Whole seconds since the last new screen, when that is long enough to say so: the values
    /// shown are old (the gathering is stuck or failed).
    pub stale_s: Option<u64>,
    /// The gathering failed: why, and what the console does about it.
    pub gathering: Option<String>,
}

/// The e-stop as the latches and the nodes' acknowledgements say.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EStopView {
    /// The namespaces whose latch is engaged (`(none)`: the plain latch, which stops every side).
    pub latched: Vec<String>,
    /// The nodes whose newest acknowledgement says they hold the e-stop.
    pub held_by: Vec<String>,
    /// The nodes whose newest acknowledgement says released.
    pub released_by: Vec<String>,
    /// An engage or release from this console is under way.
    pub pending: Option<&'static str>,
}

impl EStopView {
    /// Engaged when any latch is, or any node says it holds it.
    pub fn engaged(&self) -> bool {
        !self.latched.is_empty() || !self.held_by.is_empty()
    }
}

/// One node of the session.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NodeLine {
    pub name: String,
    /// iceoryx2's view: `alive`, `dead`, ...; `-` when only its health reports are seen.
    pub status: String,
    /// Restarts seen while the console ran (its process id changed).
    pub restarts: u32,
    /// Its newest health report, if any: how old (s) and what it says.
    pub health: Option<HealthLine>,
}

/// What a node's newest health report says.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct HealthLine {
    pub age_s: f64,
    pub loop_rate_hz: f32,
    /// Age of each input's newest sample, ms (negative: never received).
    pub input_ages_ms: Vec<f32>,
    pub timeouts: u64,
    pub errors: u64,
    /// `name=value` details.
    pub details: String,
}

/// One side's glove and hand.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct HandView {
    pub side: String,
    /// glove/state's normalised positions ([`GLOVE_CHANNELS`]), and how old, s.
    pub glove: Option<([f32; 6], f64)>,
    /// glove/force_command's forces ([`GLOVE_FINGERS`]), whether it says e-stop, how old, s.
    pub force: Option<([i16; 5], bool, f64)>,
    /// hand/tactile's normal force per fingertip (named by the hand's profile), how old, s.
    pub tactile: Option<(Vec<(String, f32)>, f64)>,
    /// hand/state: the hand's model name, link up, holding, how old, s.
    pub hand: Option<(String, bool, bool, f64)>,
}

/// A bridge's link.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LinkView {
    pub node: String,
    /// `up`, `down`, `refused` or `unknown`.
    pub state: &'static str,
    pub rtt_ms: Option<f64>,
    pub latency_p99_ms: Option<f64>,
    pub age_s: f64,
}

/// A recorder and its episode.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RecorderView {
    pub node: String,
    /// Its episode in words (`episode 3 open, 12.0 s`).
    pub episode: String,
    pub dropped: u64,
    pub age_s: f64,
}

/// Rows of one side's panel: its borders, the headings, six glove channels.
const HAND_HEIGHT: u16 = 9;
/// From this width on the tables have every column.
pub const WIDE: u16 = 110;

/// A sample older than this is shown as stale, s.
pub const STALE_S: f64 = 0.5;

/// Draws `screen` into `frame`, laid out for the frame's size.
pub fn draw(frame: &mut Frame, screen: &Screen) {
    let area = frame.area();
    // The bars before the tables: in a short terminal (two sides in 24 lines) the tables give
    // up their rows first, then each side's panel its last ones.
    let sides = screen.hands.len().max(1) as u16;
    let wanted = if screen.hands.is_empty() {
        3
    } else {
        HAND_HEIGHT * sides
    };
    let hand_height = wanted.min(area.height.saturating_sub(1 + 5 + 1));
    let [header, status, tables, hands, footer] = Layout::vertical([
        Constraint::Length(1),
        Constraint::Length(5),
        Constraint::Fill(1),
        Constraint::Length(hand_height),
        Constraint::Length(1),
    ])
    .areas(area);
    frame.render_widget(Paragraph::new(header_line(screen)), header);
    let [status, message] =
        Layout::vertical([Constraint::Length(3), Constraint::Length(2)]).areas(status);
    frame.render_widget(Paragraph::new(status_lines(screen)), status);
    // The last action's answer, on two lines if it needs them.
    frame.render_widget(
        Paragraph::new(screen.message.clone())
            .style(Style::default().add_modifier(Modifier::ITALIC))
            .wrap(Wrap { trim: true }),
        message,
    );
    // Narrow (an 80-column terminal): the node details and the transport latency are left out.
    let wide = area.width >= WIDE;
    let [nodes, topics] =
        Layout::horizontal([Constraint::Percentage(52), Constraint::Percentage(48)]).areas(tables);
    frame.render_widget(nodes_table(screen, wide), nodes);
    frame.render_widget(topics_table(screen, wide), topics);
    if screen.hands.is_empty() {
        frame.render_widget(
            Paragraph::new("no glove or hand samples yet")
                .block(Block::default().borders(Borders::ALL).title(" hands ")),
            hands,
        );
    } else {
        let rows = Layout::vertical(vec![
            Constraint::Ratio(1, u32::from(sides));
            screen.hands.len()
        ])
        .split(hands);
        for (hand, area) in screen.hands.iter().zip(rows.iter()) {
            draw_hand(frame, hand, *area);
        }
    }
    frame.render_widget(Paragraph::new(footer_line(screen)), footer);
}

/// The title and the sides, or, while the values shown are old, a red banner saying so first.
fn header_line(screen: &Screen) -> Line<'static> {
    let mut line = Line::from(Span::styled(
        " teleop top ",
        Style::default().add_modifier(Modifier::REVERSED),
    ));
    let mut warning = Vec::new();
    if let Some(age) = screen.stale_s {
        warning.push(format!("no update for {age} s: values are old"));
    }
    if let Some(gathering) = &screen.gathering {
        warning.push(gathering.clone());
    }
    if !warning.is_empty() {
        line.push_span(Span::styled(
            format!(" {} ", warning.join("; ")),
            Style::default()
                .fg(Color::White)
                .bg(Color::Red)
                .add_modifier(Modifier::BOLD),
        ));
    }
    line.push_span(Span::raw(format!(
        " sides: {}  rates over {:.1} s",
        screen.sides.join(", "),
        screen.window_s
    )));
    line
}

fn status_lines(screen: &Screen) -> Vec<Line<'static>> {
    let e = &screen.estop;
    let estop = if e.engaged() {
        let mut text = String::from(" E-STOP ENGAGED ");
        if !e.latched.is_empty() {
            text.push_str(&format!("latched: {} ", e.latched.join(", ")));
        } else {
            text.push_str("NOT latched ");
        }
        let held = if e.held_by.is_empty() {
            "no node".to_string()
        } else {
            e.held_by.join(", ")
        };
        Line::from(vec![
            Span::styled(
                text,
                Style::default()
                    .fg(Color::White)
                    .bg(Color::Red)
                    .add_modifier(Modifier::BOLD),
            ),
            Span::raw(format!(" held by {held}")),
        ])
    } else {
        let obeying = if e.released_by.is_empty() {
            "no latch".to_string()
        } else {
            format!("released by {}", e.released_by.join(", "))
        };
        Line::from(vec![
            Span::styled(" e-stop released ", Style::default().fg(Color::Green)),
            Span::raw(format!(" {obeying}")),
        ])
    };
    let mut estop = estop;
    if let Some(pending) = e.pending {
        estop.push_span(Span::styled(
            format!("  ({pending}...)"),
            Style::default().add_modifier(Modifier::BOLD),
        ));
    }
    let recording = if screen.recorders.is_empty() {
        "recording: no recorder reports".to_string()
    } else {
        let parts: Vec<String> = screen
            .recorders
            .iter()
            .map(|r| {
                format!(
                    "{}: {}, {} dropped{}",
                    r.node,
                    r.episode,
                    r.dropped,
                    stale(r.age_s)
                )
            })
            .collect();
        format!("recording: {}", parts.join("; "))
    };
    let links = if screen.links.is_empty() {
        "link: none (one station)".to_string()
    } else {
        let parts: Vec<String> = screen
            .links
            .iter()
            .map(|l| {
                let ms = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.1} ms"));
                format!(
                    "{} {}, rtt {}, p99 {}{}",
                    l.node,
                    l.state,
                    ms(l.rtt_ms),
                    ms(l.latency_p99_ms),
                    stale(l.age_s)
                )
            })
            .collect();
        format!("link: {}", parts.join("; "))
    };
    vec![estop, Line::raw(recording), Line::raw(links)]
}

/// ` (stale 2.1 s)` for an age past [`STALE_S`], else nothing.
fn stale(age_s: f64) -> String {
    if age_s > STALE_S {
        format!(" (stale {age_s:.1} s)")
    } else {
        String::new()
    }
}

fn nodes_table(screen: &Screen, wide: bool) -> Table<'static> {
    let rows = screen.nodes.iter().map(|n| {
        let mut cells = vec![n.name.clone(), n.status.clone()];
        match &n.health {
            None => cells.extend(["-", "-", "-", "-"].map(String::from)),
            Some(h) => {
                let ages: Vec<String> = h
                    .input_ages_ms
                    .iter()
                    .map(|a| {
                        if *a < 0.0 {
                            "-".to_string()
                        } else {
                            format!("{a:.0}")
                        }
                    })
                    .collect();
                cells.extend([
                    format!("{:.0}", h.loop_rate_hz),
                    ages.join(","),
                    h.timeouts.to_string(),
                    h.errors.to_string(),
                ]);
            }
        }
        cells.push(n.restarts.to_string());
        if wide {
            cells.push(n.health.as_ref().map_or(String::new(), |h| {
                format!("{}{}", h.details, stale(h.age_s))
            }));
        }
        let style = if n.status == "alive" {
            Style::default()
        } else {
            Style::default().fg(Color::Red)
        };
        Row::new(cells.into_iter().map(Cell::from)).style(style)
    });
    let mut widths = vec![
        Constraint::Length(if wide { 14 } else { 9 }),
        Constraint::Length(5),
        Constraint::Length(4),
        Constraint::Length(if wide { 9 } else { 6 }),
        Constraint::Length(3),
        Constraint::Length(3),
        Constraint::Length(3),
    ];
    let ages = if wide { "AGES_MS" } else { "AGES" };
    let mut header = vec!["NODE", "STATE", "HZ", ages, "TMO", "ERR", "RST"];
    if wide {
        widths.push(Constraint::Min(10));
        header.push("DETAILS");
    }
    Table::new(rows, widths)
        .header(Row::new(header).style(Style::default().add_modifier(Modifier::BOLD)))
        .block(Block::default().borders(Borders::ALL).title(" nodes "))
}

fn topics_table(screen: &Screen, wide: bool) -> Table<'static> {
    let ms =
        |p: Option<crate::inspect::Percentiles>| p.map_or("-".into(), |p| format!("{:.2}", p.p99));
    let rows = screen.topics.iter().map(|t| {
        let mut cells = vec![
            t.name.clone(),
            format!("{:.0}", t.rate_hz),
            t.drops.to_string(),
            ms(t.latency),
        ];
        if wide {
            cells.push(ms(t.transport));
        }
        Row::new(cells)
    });
    let mut widths = vec![
        Constraint::Min(12),
        Constraint::Length(5),
        Constraint::Length(4),
        Constraint::Length(7),
    ];
    let mut header = vec!["TOPIC", "HZ", "DROP", "LAT_P99"];
    if wide {
        widths.push(Constraint::Length(7));
        header.push("TR_P99");
    }
    Table::new(rows, widths)
        .header(Row::new(header).style(Style::default().add_modifier(Modifier::BOLD)))
        .block(
            Block::default()
                .borders(Borders::ALL)
                .title(" topics (latency ms) "),
        )
}

/// A bar of `width` cells filled to `fraction` (clamped to 0..1).
pub fn bar(fraction: f32, width: usize) -> String {
    let fraction = if fraction.is_finite() {
        fraction.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let filled = (fraction * width as f32).round() as usize;
    format!("{}{}", "█".repeat(filled), "·".repeat(width - filled))
}

fn draw_hand(frame: &mut Frame, hand: &HandView, area: Rect) {
    let title = match &hand.hand {
        Some((model, link_up, holding, age)) => format!(
            " side {}: hand {model} link {}, {}{} ",
            hand.side,
            if *link_up { "up" } else { "DOWN" },
            if *holding { "HOLDING" } else { "following" },
            stale(*age)
        ),
        None => format!(" side {}: no hand state ", hand.side),
    };
    let block = Block::default().borders(Borders::ALL).title(title);
    let inner = block.inner(area);
    frame.render_widget(block, area);
    let columns = Layout::horizontal([Constraint::Ratio(1, 3); 3]).split(inner);
    // name (6) + space + bar + space + value (7)
    let bar_width = |area: Rect| (area.width as usize).saturating_sub(16).max(1);

    let w = bar_width(columns[0]);
    let mut lines = vec![header("glove position", hand.glove.map(|g| g.1))];
    if let Some((position, _)) = hand.glove {
        for (name, p) in GLOVE_CHANNELS.iter().zip(position) {
            lines.push(Line::raw(format!(
                "{:<6} {} {:>5.2}",
                short(name),
                bar(p, w),
                p
            )));
        }
    }
    frame.render_widget(Paragraph::new(lines), columns[0]);

    let w = bar_width(columns[1]);
    let mut lines = vec![header("glove force", hand.force.map(|f| f.2))];
    if let Some((force, estop, _)) = hand.force {
        if estop {
            lines[0].push_span(Span::styled(
                " E-STOP",
                Style::default().fg(Color::Red).add_modifier(Modifier::BOLD),
            ));
        }
        for (name, f) in GLOVE_FINGERS.iter().zip(force) {
            lines.push(Line::raw(format!(
                "{:<6} {} {:>5}",
                short(name),
                bar(f32::from(f).abs() / GLOVE_FORCE_FULL_SCALE, w),
                f
            )));
        }
    }
    frame.render_widget(Paragraph::new(lines), columns[1]);

    let w = bar_width(columns[2]);
    let mut lines = vec![header("tactile N", hand.tactile.as_ref().map(|t| t.1))];
    if let Some((tips, _)) = &hand.tactile {
        for (name, n) in tips {
            lines.push(Line::raw(format!(
                "{:<6} {} {:>5.1}",
                short(name),
                bar(n / TACTILE_FULL_SCALE_N, w),
                n
            )));
        }
    }
    frame.render_widget(Paragraph::new(lines), columns[2]);
}

/// A column's heading, with the newest sample's staleness (or that none came).
fn header(what: &str, age_s: Option<f64>) -> Line<'static> {
    let text = match age_s {
        None => format!("{what}: no samples"),
        Some(age) => format!("{what}{}", stale(age)),
    };
    Line::styled(text, Style::default().add_modifier(Modifier::BOLD))
}

/// A finger's name in at most 6 characters (`thumb_rotation` as `th_rot`).
fn short(name: &str) -> String {
    if name == "thumb_rotation" {
        "th_rot".into()
    } else {
        name.chars().take(6).collect()
    }
}

fn footer_line(screen: &Screen) -> Line<'static> {
    match &screen.prompt {
        Prompt::None => Line::from(vec![
            Span::styled(
                " e/space/Esc E-STOP ",
                Style::default()
                    .fg(Color::White)
                    .bg(Color::Red)
                    .add_modifier(Modifier::BOLD),
            ),
            Span::raw(" r release  s start  k success  f failure  d discard  q quit"),
        ]),
        Prompt::ConfirmRelease => Line::styled(
            " release the e-stop on every side? y: release, any other key: keep it engaged",
            Style::default().add_modifier(Modifier::BOLD),
        ),
        Prompt::Task(text) => Line::from(vec![
            Span::styled(
                " Esc E-STOP ",
                Style::default()
                    .fg(Color::White)
                    .bg(Color::Red)
                    .add_modifier(Modifier::BOLD),
            ),
            Span::raw(format!(
                " task (Enter starts, empty Enter cancels): {text}_"
            )),
        ]),
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use ratatui::backend::TestBackend;
    use ratatui::Terminal;

    use super::*;
    use crate::inspect::Percentiles;

    /// `screen` drawn at `width` x `height`, as lines of text.
    fn drawn(screen: &Screen, width: u16, height: u16) -> Vec<String> {
        let mut terminal = Terminal::new(TestBackend::new(width, height)).unwrap();
        terminal.draw(|f| draw(f, screen)).unwrap();
        let buffer = terminal.backend().buffer();
        (0..height)
            .map(|y| (0..width).map(|x| buffer[(x, y)].symbol()).collect())
            .collect()
    }

    fn session() -> Screen {
        Screen {
            sides: vec!["(none)".into()],
            window_s: 2.0,
            estop: EStopView {
                released_by: vec!["feedback".into(), "revo2".into()],
                ..Default::default()
            },
            nodes: vec![NodeLine {
                name: "feedback".into(),
                status: "alive".into(),
                restarts: 1,
                health: Some(HealthLine {
                    age_s: 0.1,
                    loop_rate_hz: 1000.0,
                    input_ages_ms: vec![1.0, -1.0],
                    timeouts: 2,
                    errors: 0,
                    details: "passivity_acted=0".into(),
                }),
            }],
            topics: vec![TopicSummary {
                name: "glove/state".into(),
                rate_hz: 500.0,
                samples: 1000,
                drops: 0,
                latency: Some(Percentiles {
                    p50: 0.1,
                    p99: 0.25,
                    max: 0.3,
                }),
                transport: None,
            }],
            hands: vec![HandView {
                side: "(none)".into(),
                glove: Some(([1.0, 0.5, 0.0, 0.25, 0.75, 0.5], 0.01)),
                force: Some(([0, 0, 0, 500, 800], false, 0.01)),
                tactile: Some((vec![("thumb".into(), 10.0), ("index".into(), 2.5)], 0.01)),
                hand: Some(("revo2".into(), true, false, 0.01)),
            }],
            links: vec![],
            recorders: vec![RecorderView {
                node: "recorder".into(),
                episode: "episode 2 open, 3.5 s".into(),
                dropped: 0,
                age_s: 0.2,
            }],
            message: "e-stop released".into(),
            prompt: Prompt::None,
            stale_s: None,
            gathering: None,
        }
    }

    fn find<'a>(lines: &'a [String], what: &str) -> &'a str {
        lines
            .iter()
            .find(|l| l.contains(what))
            .unwrap_or_else(|| panic!("{what:?} not on screen:\n{}", lines.join("\n")))
    }

    #[test]
    fn bars_fill_to_their_fraction() {
        assert_eq!(bar(0.5, 4), "██··");
        assert_eq!(bar(2.0, 3), "███");
        assert_eq!(bar(f32::NAN, 2), "··");
        assert_eq!(bar(-1.0, 2), "··");
    }

    #[test]
    fn a_running_session_shows_every_part_at_80_by_24() {
        let lines = drawn(&session(), 80, 24);
        let all = lines.join("\n");
        assert!(find(&lines, "e-stop released").contains("released by feedback, revo2"));
        assert!(find(&lines, "recording:").contains("recorder: episode 2 open, 3.5 s"));
        let node = find(&lines, "feedback ");
        for part in ["alive", "1000", "1,-", " 2 "] {
            assert!(node.contains(part), "{part:?} in {node:?}\n{all}");
        }
        let topic = find(&lines, "glove/state");
        assert!(topic.contains("500") && topic.contains("0.25"), "{all}");
        // Bars: index position 0.25 and force 500 of 1000; the thumb's 10 N fills its bar.
        let index = find(&lines, "│index ");
        assert!(index.contains("0.25") && index.contains("500"), "{all}");
        let first_row = find(&lines, "│little ");
        assert!(
            first_row.contains("thumb ") && first_row.contains("10.0"),
            "{all}"
        );
        assert!(find(&lines, "side (none)").contains("hand revo2 link up, following"));
        assert!(
            lines[23].contains("E-STOP") && lines[23].contains("q quit"),
            "{all}"
        );
    }

    #[test]
    fn the_layout_follows_the_size() {
        let screen = session();
        let lines = drawn(&screen, 160, 50);
        // The footer is on the last line whatever the height, the bars are wider.
        assert!(lines[49].contains("q quit"));
        let narrow = drawn(&screen, 80, 24);
        let bar_cells = |lines: &[String]| {
            find(lines, "little ")
                .chars()
                .filter(|c| *c == '█' || *c == '·')
                .count()
        };
        assert!(bar_cells(&lines) > bar_cells(&narrow));
        // Too small to hold it all: drawn without panicking.
        drawn(&screen, 20, 5);
    }

    #[test]
    fn two_sides_keep_their_forces_and_the_keys_in_80_by_24() {
        let mut screen = session();
        let mut right = screen.hands[0].clone();
        right.side = "right".into();
        right.force = Some(([1, 2, 3, 4, 5], false, 0.01));
        screen.hands[0].side = "left".into();
        screen.hands.push(right);
        for (width, height) in [(80, 24), (120, 40)] {
            let lines = drawn(&screen, width, height);
            let all = lines.join("\n");
            assert!(
                all.contains("side left:") && all.contains("side right:"),
                "{all}"
            );
            assert!(lines[usize::from(height) - 1].contains("q quit"), "{all}");
            for finger in ["little", "ring", "middle", "index", "thumb"] {
                let rows = lines
                    .iter()
                    .filter(|l| l.contains(&format!("│{finger} ")))
                    .count();
                assert_eq!(rows, 2, "{finger} of both sides\n{all}");
            }
        }
    }

    #[test]
    fn a_link_between_stations_is_shown_with_its_round_trip() {
        let mut screen = session();
        screen.links = vec![LinkView {
            node: "bridge".into(),
            state: "up",
            rtt_ms: Some(41.25),
            latency_p99_ms: None,
            age_s: 0.2,
        }];
        let lines = drawn(&screen, 80, 24);
        assert!(find(&lines, "link: ").contains("link: bridge up, rtt 41.2 ms, p99 -"));
        screen.links[0].age_s = 3.0;
        let lines = drawn(&screen, 80, 24);
        assert!(find(&lines, "link: ").contains("(stale 3.0 s)"));
    }

    #[test]
    fn an_engaged_estop_and_the_prompts_are_shown() {
        let mut screen = session();
        screen.estop = EStopView {
            latched: vec!["(none)".into()],
            held_by: vec!["feedback".into(), "revo2".into()],
            released_by: vec![],
            pending: None,
        };
        screen.hands[0].force = Some(([0; 5], true, 0.01));
        screen.hands[0].hand = Some(("revo2".into(), true, true, 0.01));
        screen.prompt = Prompt::ConfirmRelease;
        let lines = drawn(&screen, 80, 24);
        let estop = find(&lines, "E-STOP ENGAGED");
        assert!(estop.contains("latched: (none)") && estop.contains("held by feedback, revo2"));
        assert!(find(&lines, "glove force").contains("E-STOP"));
        assert!(find(&lines, "side (none)").contains("HOLDING"));
        assert!(lines[23].contains("y: release"));
        screen.prompt = Prompt::Task("pick the ball".into());
        let lines = drawn(&screen, 80, 24);
        assert!(lines[23].contains("Esc E-STOP") && lines[23].contains("pick the ball_"));
    }

    #[test]
    fn old_values_and_a_failed_gathering_are_shown_first() {
        let mut screen = session();
        let lines = drawn(&screen, 80, 24);
        assert!(!lines[0].contains("values are old"));
        screen.stale_s = Some(3);
        let lines = drawn(&screen, 80, 24);
        assert!(
            lines[0].starts_with(" teleop top  no update for 3 s: values are old "),
            "{}",
            lines[0]
        );
        screen.gathering = Some("gathering failed (gone); starting it again".into());
        let lines = drawn(&screen, 120, 24);
        assert!(
            lines[0].contains("values are old; gathering failed (gone); starting it again"),
            "{}",
            lines[0]
        );
    }
}
