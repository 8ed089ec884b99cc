//! The topic tables of docs/protocols/ros1.md, ros2.md and rosbridge.md say what the
//! adapters' tables (`api::ros1::topics::TOPICS`, `api::ros2::topics`,
//! `api::rosbridge::topics::TOPICS`) publish: the same
//! topics, each of the same type at the same rate, so a topic added to a table and not to
//! its page (or the other way round) fails here.

use std::collections::BTreeMap;
use std::time::Duration;

use chassisd::api::ros1::topics as ros1;
use chassisd::api::ros2::topics as ros2;
use chassisd::api::rosbridge::topics as rosbridge;
use chassisd::engine::STATUS_PERIOD;
use chassisd::vehicle::chassis::CONTROL_PERIOD;

use crate::common;

/// The rows of the table of docs/protocols/`page` whose header starts with `header`: its
/// first cell (the topic, without its backticks) to the others.
fn table(page: &str, header: &str) -> BTreeMap<String, Vec<String>> {
    let text = std::fs::read_to_string(common::repo().join("docs/protocols").join(page))
        .expect("readable page");
    let mut lines = text.lines().skip_while(|l| !l.starts_with(header));
    assert!(lines.next().is_some(), "{page}: no table {header}");
    lines
        .skip(1)
        .take_while(|l| l.starts_with('|'))
        .map(|row| {
            let mut cells = row
                .trim_matches('|')
                .split('|')
                .map(|c| c.trim().to_owned());
            let topic = cells.next().unwrap_or_default().replace('`', "");
            (topic, cells.collect())
        })
        .collect()
}

/// "N Hz" for one message every `period`.
fn hz(period: Duration) -> String {
    format!("{} Hz", (1.0 / period.as_secs_f64()).round())
}

#[test]
fn the_ros1_page_lists_every_topic_the_node_publishes() {
    let documented = table("ros1.md", "| Topic | Type | Rate |");
    let names: Vec<&str> = ros1::TOPICS.iter().map(|t| t.name).collect();
    assert_eq!(
        documented.keys().map(String::as_str).collect::<Vec<_>>(),
        {
            let mut sorted = names.clone();
            sorted.sort_unstable();
            sorted
        },
        "docs/protocols/ros1.md's topics are not the node's"
    );
    for topic in ros1::TOPICS {
        let row = &documented[topic.name];
        assert_eq!(row[0], topic.msg_type, "{}'s type", topic.name);
        let rate = &row[1];
        let expected = match topic.publish {
            ros1::Publish::Poses { period, .. } => hz(period.unwrap_or(CONTROL_PERIOD)),
            ros1::Publish::Imu(_) => "the IMU's".to_owned(),
            ros1::Publish::Status { every, .. } => hz(STATUS_PERIOD * every as u32),
            ros1::Publish::Code(_) => "on ".to_owned(),
        };
        assert!(
            rate.starts_with(&expected),
            "{}: the page says {rate:?}, the table {expected:?}",
            topic.name
        );
    }
}

#[test]
fn the_rosbridge_page_lists_every_topic_the_server_has() {
    let documented = table("rosbridge.md", "| Topic | Type (ROS 2) | Direction, rate |");
    let mut names: Vec<&str> = rosbridge::TOPICS.iter().map(|t| t.name).collect();
    names.sort_unstable();
    assert_eq!(
        documented.keys().map(String::as_str).collect::<Vec<_>>(),
        names,
        "docs/protocols/rosbridge.md's topics are not the server's"
    );
    for topic in rosbridge::TOPICS {
        let row = &documented[topic.name];
        assert!(
            rosbridge::type_matches(topic, &row[0]),
            "{}: the page says {}, the table {}",
            topic.name,
            row[0],
            topic.msg_type
        );
        let direction = &row[1];
        let expected = match topic.flow {
            rosbridge::Flow::Subscribed => "subscribed".to_owned(),
            rosbridge::Flow::Published(rosbridge::Publish::Status { every, .. }) => {
                format!("published, {}", hz(STATUS_PERIOD * every as u32))
            }
            rosbridge::Flow::Published(rosbridge::Publish::Odometry { every, .. }) => {
                format!("published, {}", hz(CONTROL_PERIOD * every as u32))
            }
            rosbridge::Flow::Published(rosbridge::Publish::Latched(_)) => {
                "published on change, and at once to a new subscriber".to_owned()
            }
            rosbridge::Flow::Published(rosbridge::Publish::Event(_)) => {
                "published on each event".to_owned()
            }
        };
        assert!(
            direction.starts_with(&expected),
            "{}: the page says {direction:?}, the table {expected:?}",
            topic.name
        );
    }
}

/// A QoS as docs/protocols/ros2.md writes it: `reliable, volatile, 10`.
fn qos_words(qos: ros2::Qos) -> String {
    let reliability = match qos.reliability {
        ros2::Reliability::Reliable => "reliable",
        ros2::Reliability::BestEffort => "best effort",
    };
    let durability = match qos.durability {
        ros2::Durability::Volatile => "volatile",
        ros2::Durability::TransientLocal => "transient local",
    };
    format!("{reliability}, {durability}, {}", qos.depth)
}

#[test]
fn the_ros2_page_lists_every_topic_the_node_has_with_its_qos() {
    // /cmd_vel has two types: the rows are keyed by topic and type.
    let text = std::fs::read_to_string(common::repo().join("docs/protocols/ros2.md"))
        .expect("readable page");
    let header = "| Topic | Type | QoS | Rate | What |";
    let rows: BTreeMap<(String, String), Vec<String>> = text
        .lines()
        .skip_while(|l| !l.starts_with(header))
        .skip(2)
        .take_while(|l| l.starts_with('|'))
        .map(|row| {
            let cells: Vec<String> = row
                .trim_matches('|')
                .split('|')
                .map(|c| c.trim().replace('`', ""))
                .collect();
            ((cells[0].clone(), cells[1].clone()), cells[2..].to_vec())
        })
        .collect();
    let mut expected: Vec<(String, String)> = ros2::TOPICS
        .iter()
        .map(|t| (t.name.to_owned(), t.msg_type.to_owned()))
        .chain(
            ros2::TAKEN
                .iter()
                .map(|t| (t.name.to_owned(), t.msg_type.to_owned())),
        )
        .collect();
    expected.sort();
    assert_eq!(
        rows.keys().cloned().collect::<Vec<_>>(),
        expected,
        "docs/protocols/ros2.md's topics are not the node's"
    );
    for topic in ros2::TOPICS {
        let row = &rows[&(topic.name.to_owned(), topic.msg_type.to_owned())];
        assert_eq!(row[0], qos_words(topic.qos), "{}'s QoS", topic.name);
        let rate = match topic.publish {
            ros2::Publish::State(rosbridge::Publish::Status { every, .. }) => {
                hz(STATUS_PERIOD * every as u32)
            }
            ros2::Publish::State(rosbridge::Publish::Odometry { .. }) => "50 Hz".to_owned(),
            ros2::Publish::State(rosbridge::Publish::Latched(_)) => "on change".to_owned(),
            ros2::Publish::State(rosbridge::Publish::Event(_)) => "on each event".to_owned(),
            ros2::Publish::Imu(_) => "the IMU's".to_owned(),
            ros2::Publish::Fix(_) => "the receiver's".to_owned(),
            ros2::Publish::Static(_) => "once".to_owned(),
        };
        assert!(
            row[1].starts_with(&rate),
            "{}: the page says {:?}, the table {rate:?}",
            topic.name,
            row[1]
        );
    }
    for taken in ros2::TAKEN {
        let row = &rows[&(taken.name.to_owned(), taken.msg_type.to_owned())];
        let words = qos_words(taken.qos);
        let reliability = words.split(',').next().unwrap_or_default();
        assert!(
            row[0].starts_with(&format!("taken {reliability}")),
            "{} ({}): the page says {:?}, the table {words:?}",
            taken.name,
            taken.msg_type,
            row[0]
        );
    }
}
