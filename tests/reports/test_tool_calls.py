"""Tool calls (schema version 5, issue 28) reach every reader: ``recap sql`` (the tool_calls table and
the tool_stats view), ``recap show`` (the transcript of calls and results), the viewer's episode page
and a call's window (everything model-written escaped); a run written under version 4 (no tool_calls
table, messages without the tool columns) reads everywhere as one without tool calls, and can be
continued."""

from __future__ import annotations

import http.client
import json
import re
import shutil
from pathlib import Path

import pytest

from pipeline.cli import main as cli_main
from pipeline.store import RunStore
from reports.toolcalls import MessageCall, message_calls, one_line
from reports.views import open_runs, run_query
from reports.webview.server import serve, stop
from schemas.parts import PartWriter, read_table
from schemas.records import MessageRecord, ToolCallRecord
from schemas.tables import arrow_schema
from tests.doubles.tool_run import as_version_4, write_tool_run


@pytest.fixture(scope="module")
def tool_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_tool_run(tmp_path_factory.mktemp("tools") / "runT")


@pytest.fixture(scope="module")
def v4_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return as_version_4(write_tool_run(tmp_path_factory.mktemp("tools4") / "runT"))


def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, list[str], str]:
    code = cli_main(argv)
    out, err = capsys.readouterr()
    return code, out.splitlines(), err


def _page(run_dir: Path, path: str) -> tuple[int, str]:
    server, thread = serve([run_dir], 0, poll_s=0)
    try:
        conn = http.client.HTTPConnection("127.0.0.1", server.server_address[1], timeout=30)
        conn.request("GET", path)
        r = conn.getresponse()
        return r.status, r.read().decode()
    finally:
        stop(server, thread)


# -- recap sql -------------------------------------------------------------------------------------


def test_recap_sql_reads_the_tool_calls_rows(tool_run, capsys):
    q = (
        'SELECT episode_id, "index", step_index, call_id, message_seq, name, arguments, valid, exit_code, duration_s, '
        'output_bytes, timed_out, error FROM tool_calls ORDER BY episode_id, "index"'
    )
    code, out, err = _run(["sql", str(tool_run), "--csv", q], capsys)
    assert (code, err) == (0, "")
    assert out == [
        "episode_id,index,step_index,call_id,message_seq,name,arguments,valid,exit_code,duration_s,output_bytes,timed_out,error",
        'swe-a-1,0,0,c1,1,bash,"{""command"": ""ls""}",True,0,0.25,12,False,',
        'swe-a-1,1,1,c2,1,bash,"{""command"": ""sleep 99""}",True,,10.0,0,True,',
        'swe-a-1,2,2,c3,4,<b>nosuch</b>,"{not json <img src=x onerror=""alert(1)"">",False,,0.0,0,False,arguments are not JSON: <img src=x>',
        'swe-b-1,0,0,,,bash,"{""command"": ""cat a.txt""}",True,1,0.5,30,False,',
    ]


def test_the_tool_stats_view_counts_each_episodes_calls(tool_run, capsys):
    code, out, _ = _run(["sql", str(tool_run), "--csv", "SELECT * EXCLUDE (run_id) FROM tool_stats ORDER BY episode_id"], capsys)
    assert code == 0
    assert out == [
        "episode_id,tool_calls,invalid_calls,timed_out,nonzero_exits,tools,duration_s,output_bytes",
        "swe-a-1,3,1,1,0,2,10.25,12",
        "swe-b-1,1,0,0,1,1,0.5,30",
    ]


def test_messages_carry_their_tool_fields_in_sql(tool_run, capsys):
    q = "SELECT seq, role, tool_call_id, tool_calls IS NOT NULL AS calls FROM messages WHERE episode_id = 'swe-a-1' ORDER BY seq"
    code, out, _ = _run(["sql", str(tool_run), "--csv", q], capsys)
    assert code == 0
    assert out == [
        "seq,role,tool_call_id,calls",
        "0,user,,False",
        "1,assistant,,True",
        "2,tool,c1,False",
        "3,tool,c2,False",
        "4,assistant,,True",
        "5,tool,c3,False",
        "6,assistant,,False",
    ]


# -- recap show ------------------------------------------------------------------------------------


def test_recap_show_prints_the_tool_call_transcript(tool_run, capsys):
    code, out, err = _run(["show", str(tool_run), "swe-a-1"], capsys)
    assert (code, err) == (0, "")
    assert out == [
        "swe-a-1  swe/lite/swe-a  react / scripted  success  steps 3  calls 3  $0.0000",
        '├── bash {"command": "ls"} ok  a.txt | b.txt',
        '├── bash {"command": "sleep 99"} ok  error: timed out after 10 s',
        '└── <b>nosuch</b> {not json <img src=x onerror="alert(1)"> invalid  error: arguments are not JSON',
        "tool calls: 3 (1 invalid, 1 timed out) · 10.25 s · 12 output bytes",
        '  #1 assistant call bash {"command": "ls"} [c1]',
        '  #1 assistant call bash {"command": "sleep 99"} [c2]',
        "  #2 tool [c1] (exit 0 · 0.25 s · 12 bytes) a.txt",
        "  #3 tool [c2] (timed out after 10.00 s · 0 bytes) error: timed out after 10 s",
        "  #4 assistant: Trying <script>x</script>",
        '  #4 assistant call <b>nosuch</b> {not json <img src=x onerror="alert(1)"> [c3]',
        "  #5 tool [c3] (invalid: arguments are not JSON: <img src=x>) error: arguments are not JSON",
    ]


def test_recap_show_lists_commands_written_as_text(tool_run, capsys):
    code, out, _ = _run(["show", str(tool_run), "swe-b"], capsys)
    assert code == 0
    assert out == [
        "swe-b-1  swe/lite/swe-b  react / scripted  step_cap  steps 1  calls 1  $0.0000",
        "└── cat a.txt ok  cat: a.txt: No such file",
        "tool calls: 1 (0 invalid, 0 timed out) · 0.50 s · 30 output bytes",
        '  step 0 command bash {"command": "cat a.txt"}: exit 1 · 0.50 s · 30 bytes',
    ]


def test_model_written_markup_and_line_breaks_stay_text_on_one_line(tmp_path, capsys):
    """Arguments that read as rich markup or hold line breaks and escape codes print as they are, one line each."""
    run = write_tool_run(tmp_path / "run")
    calls = json.dumps([{"id": "k[/]", "name": "[bold]x[/bold]", "arguments": "a\nb\x1b[31m :smile:"}])
    PartWriter(run, "extra").write_records(
        "runT",
        [
            MessageRecord("swe-b-1", 2, "assistant", "reply", "", tool_calls=calls),
            MessageRecord("swe-b-1", 3, "tool", "tool_result", "[red]out[/red]\nmore", tool_call_id="k[/]"),
            ToolCallRecord("swe-b-1", 1, 1, "[bold]x[/bold]", "a\nb\x1b[31m :smile:", True, "k[/]", 2, exit_code=0),
        ],
    )
    code, out, err = _run(["show", str(run), "swe-b-1"], capsys)
    assert (code, err) == (0, "")
    assert out[2:] == [
        "tool calls: 2 (0 invalid, 0 timed out) · 0.50 s · 30 output bytes",
        "  #2 assistant call [bold]x[/bold] a\\nb[31m :smile: [k[/]]",
        "  #3 tool [k[/]] (exit 0 · 0.00 s · 0 bytes) [red]out[/red]",
        '  step 0 command bash {"command": "cat a.txt"}: exit 1 · 0.50 s · 30 bytes',
    ]


# -- the viewer ------------------------------------------------------------------------------------


def test_the_episode_page_shows_calls_results_and_the_tool_call_table_escaped(tool_run):
    status, body = _page(tool_run, "/episode?id=swe-a-1")
    assert status == 200
    # nothing the model wrote reaches the page as markup
    assert "<img" not in body and "<script>x" not in body and "<b>nosuch" not in body
    section = re.search(r'<section id="tool-calls">(.*?)</section>', body, re.S)
    assert section is not None
    rows = re.findall(r"<tr[^>]*data-tool-call[^>]*>(.*?)</tr>", section.group(1))
    cells = [re.findall(r"<td[^>]*>(.*?)</td>", r) for r in rows]
    assert cells == [
        ["0", "0", '<a href="#msg-1">#1</a>', "c1", "<code>bash</code>", "<code>{&quot;command&quot;: &quot;ls&quot;}</code>"]
        + ["yes", "0", "0.25 s", "12", "", ""],
        [
            "1",
            "1",
            '<a href="#msg-1">#1</a>',
            "c2",
            "<code>bash</code>",
            "<code>{&quot;command&quot;: &quot;sleep 99&quot;}</code>",
        ]
        + ["yes", "", "10.00 s", "0", "yes", ""],
        [
            "2",
            "2",
            '<a href="#msg-4">#4</a>',
            "c3",
            "<code>&lt;b&gt;nosuch&lt;/b&gt;</code>",
            "<code>{not json &lt;img src=x onerror=&quot;alert(1)&quot;&gt;</code>",
            "no",
            "",
            "0.00 s",
            "0",
            "",
            "arguments are not JSON: &lt;img src=x&gt;",
        ],
    ]
    assert '<p class="tool-summary">tool calls: 3 (1 invalid, 1 timed out) · 10.25 s · 12 output bytes</p>' in section.group(1)
    # the assistant message's calls and the tool results, with the call each answers
    assert (
        '<li class="msg assistant" id="msg-1" data-seq="1"><span class="tag">#1 assistant · reply</span><ol class="tool-calls">'
        '<li data-call-id="c1">call <code>bash</code> <code>{&quot;command&quot;: &quot;ls&quot;}</code> <span class="tag">id c1</span></li>'
        '<li data-call-id="c2">call <code>bash</code> <code>{&quot;command&quot;: &quot;sleep 99&quot;}</code> '
        '<span class="tag">id c2</span></li></ol></li>'
    ) in body
    assert (
        '<li class="msg tool" id="msg-2" data-seq="2"><span class="tag">#2 tool · tool_result · answers call c1</span>'
        "<pre>a.txt\nb.txt</pre></li>"
    ) in body
    assert (
        '<span class="tag">#4 assistant · reply</span><pre>Trying &lt;script&gt;x&lt;/script&gt;</pre><ol class="tool-calls">'
        '<li data-call-id="c3">call <code>&lt;b&gt;nosuch&lt;/b&gt;</code> '
        '<code>{not json &lt;img src=x onerror=&quot;alert(1)&quot;&gt;</code> <span class="tag">id c3</span></li></ol>'
    ) in body


def test_a_calls_window_shows_the_tool_calls_it_was_sent(tool_run):
    status, body = _page(tool_run, "/window?id=swe-a-1&call=1&fragment=1")
    assert status == 200
    assert [int(s) for s in re.findall(r'<li class="msg [a-z]+" id="msg-\d+" data-seq="(\d+)"', body)] == [0, 1, 2, 3]
    assert '<li data-call-id="c2">call <code>bash</code>' in body
    assert "#3 tool · tool_result · answers call c2</span><pre>error: timed out after 10 s</pre>" in body


def test_a_text_action_episode_lists_its_command_and_no_message_calls(tool_run):
    status, body = _page(tool_run, "/episode?id=swe-b-1")
    assert status == 200 and '<section id="tool-calls">' in body  # its text command is a tool_calls row
    assert re.findall(r"data-tool-call=\"(\d+)\"", body) == ["0"]
    assert "answers call" not in body and 'class="tool-calls"' not in body


# -- the helpers -----------------------------------------------------------------------------------


def test_message_calls_read_the_runtimes_json_and_refuse_anything_else():
    assert message_calls(None) == []
    assert message_calls('[{"id": "a", "name": "bash", "arguments": "{}"}]') == [MessageCall("a", "bash", "{}")]
    assert message_calls('[{"id": "a", "name": "bash", "arguments": {"x": 1}}]') == [MessageCall("a", "bash", '{"x": 1}')]
    assert message_calls("not json") is None and message_calls('{"id": "a"}') is None and message_calls("[1]") is None
    assert one_line("a\nb\tc\\d\x07", 80) == "a\\nb\\tc\\\\d" and one_line("x" * 10, 6) == "xxx..."


# -- a run written under schema version 4 ------------------------------------------------------------


def test_a_version_4_run_reads_as_one_without_tool_calls(v4_run, capsys):
    assert not (v4_run / "tool_calls").exists()
    msgs, bad = read_table(v4_run, "messages")
    assert bad == [] and msgs.schema == arrow_schema("messages")
    assert {(m["tool_call_id"], m["tool_calls"]) for m in msgs.to_pylist()} == {(None, None)}
    q = (
        "SELECT (SELECT count(*) FROM tool_calls) AS calls, (SELECT count(*) FROM tool_stats) AS stats, "
        "(SELECT count(*) FROM messages WHERE tool_call_id IS NOT NULL OR tool_calls IS NOT NULL) AS tool_msgs, "
        "(SELECT count(*) FROM messages) AS msgs, (SELECT count(*) FROM bad_parts) AS bad"
    )
    code, out, err = _run(["sql", str(v4_run), "--csv", q], capsys)
    assert (code, err, out) == (0, "", ["calls,stats,tool_msgs,msgs,bad", "0,0,0,9,0"])
    code, out, err = _run(["show", str(v4_run), "swe-a-1"], capsys)
    assert (code, err) == (0, "")
    assert out == [
        "swe-a-1  swe/lite/swe-a  react / scripted  success  steps 3  calls 3  $0.0000",
        '├── bash {"command": "ls"} ok  a.txt | b.txt',
        '├── bash {"command": "sleep 99"} ok  error: timed out after 10 s',
        '└── <b>nosuch</b> {not json <img src=x onerror="alert(1)"> invalid  error: arguments are not JSON',
    ]
    code, out, err = _run(["status", str(v4_run)], capsys)
    assert (code, err) == (0, "")
    assert out[-1] == "units 2/2 done, 1 succeeded, 0 stopped by a budget cap, 0 not finished; spend $0.0000"
    assert not any("unreadable" in line or "skipped" in line for line in out)
    status, body = _page(v4_run, "/episode?id=swe-a-1")
    assert status == 200 and '<section id="tool-calls">' not in body and "answers call" not in body
    assert "Messages (7)" in body


def test_recap_report_reads_a_version_4_run(v4_run, tmp_path, capsys):
    code, _, err = _run(["report", str(v4_run), "--format", "csv,html", "--out", str(tmp_path / "rep")], capsys)
    assert (code, err) == (0, "")
    rows = (tmp_path / "rep" / "csv" / "viewer_messages.csv").read_text().splitlines()
    assert rows[0] == "run_id,episode_id,seq,role,kind,node_id,pinned,content" and len(rows) > 1
    assert (tmp_path / "rep" / "csv" / "skipped_parts.csv").read_text().splitlines()[1:] == []


def test_a_version_4_run_is_continued_and_old_and_new_messages_read_as_one_table(v4_run, tmp_path):
    run = Path(shutil.copytree(v4_run, tmp_path / "runT"))
    ident = RunStore(run).check_can_hold("toolrun")
    assert ident is not None and (ident.run_id, ident.schema_version) == ("runT", 4)
    PartWriter(run, "new").write_records(
        "runT",
        [
            MessageRecord("swe-c-1", 0, "assistant", "reply", "", tool_calls='[{"id": "z", "name": "bash", "arguments": "{}"}]'),
            MessageRecord("swe-c-1", 1, "tool", "tool_result", "ok", tool_call_id="z"),
            ToolCallRecord("swe-c-1", 0, 0, "bash", "{}", True, "z", 0, exit_code=0),
        ],
    )
    msgs, bad = read_table(run, "messages")
    assert bad == []
    tools = [(m["episode_id"], m["seq"], m["tool_call_id"]) for m in msgs.to_pylist() if m["tool_calls"] or m["tool_call_id"]]
    assert sorted(tools) == [("swe-c-1", 0, None), ("swe-c-1", 1, "z")]
    assert msgs.num_rows == 11
    calls, bad = read_table(run, "tool_calls")
    assert bad == [] and [(r["episode_id"], r["call_id"]) for r in calls.to_pylist()] == [("swe-c-1", "z")]
    con = open_runs([run])  # the views: the version 4 parts mapped, the new ones as written, one table
    try:
        q = "SELECT count(*), count(tool_call_id), count(tool_calls), (SELECT count(*) FROM tool_stats) FROM messages"
        assert run_query(con, q).rows == [(11, 1, 1, 1)]
    finally:
        con.close()


def test_recap_show_previews_a_tool_result_by_its_output_not_the_prompt_around_it():
    """Issue 36 item 7: ReCAP's tool message wraps the command's output in its prompt (``Latest observation:``
    first); ``recap show`` previews the output: the first line of the call's step's observation."""
    from pipeline.show import tool_call_lines
    from recap.recap_tool_prompts import action_taken_prompt

    output = "\n3 passed in 0.12s\nok"
    content = action_taken_prompt(observation=output, task="Fix add", subtasks=["run the tests"])
    assert content.splitlines()[0] != "3 passed in 0.12s"  # the template's first line is not the output's
    calls = json.dumps([{"id": "c1", "type": "function", "function": {"name": "bash", "arguments": '{"command": "pytest"}'}}])
    messages = [
        {"seq": 4, "role": "assistant", "tool_calls": calls, "tool_call_id": None, "content": ""},
        {"seq": 5, "role": "tool", "tool_calls": None, "tool_call_id": "c1", "content": content},
    ]
    row = {
        "index": 0, "step_index": 2, "call_id": "c1", "message_seq": 4, "name": "bash", "arguments": '{"command": "pytest"}',
        "valid": True, "error": "", "exit_code": 0, "duration_s": 0.5, "output_bytes": 24, "timed_out": False,
    }  # fmt: skip
    steps = [{"index": 2, "observation": output}]
    lines = [t.plain for t in tool_call_lines([row], messages, steps)]
    assert lines[-1] == "  #5 tool [c1] (exit 0 · 0.50 s · 24 bytes) 3 passed in 0.12s"
