"""The fleet page's HTML templates (jinja2, autoescaped).  No JavaScript of ours: the plots
are plotly's, acknowledgement is a plain HTML form that `monitor fleet serve` answers."""

from __future__ import annotations

BASE = """<!doctype html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{{ title }}</title>
{% if plots %}<script src="plotly.min.js"></script>{% endif %}
<style>
body { font-family: system-ui, sans-serif; margin: 0 1.5em 2em; color: #222; }
nav { padding: .6em 0; border-bottom: 1px solid #ccc; margin-bottom: .8em; }
nav a { margin-right: 1.2em; font-weight: 600; }
table { border-collapse: collapse; margin: .6em 0 1.2em; font-size: 14px; }
th, td { border: 1px solid #ccc; padding: .3em .5em; text-align: left; vertical-align: top; }
th { background: #f0f0f0; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
.state { font-weight: 700; padding: .1em .4em; border-radius: 3px; white-space: nowrap; }
.fault { background: #f8d0d0; color: #8b0000; } .sensor_fault { background: #ffe0b8; color:
#7a3d00; }
.wearing { background: #fff3b0; color: #6b5800; } .healthy { background: #d4efd4; color: #1b5e20; }
.not_judged, .error, .uncommissioned { background: #e4e4e4; color: #444; }
.note { color: #555; font-size: 13px; max-width: 70em; }
.banner { background: #eef4ff; border: 1px solid #b8cff5; padding: .5em .8em; max-width: 70em; }
form.ack { display: flex; gap: .3em; flex-wrap: wrap; }
form.ack input[type=text] { width: 8em; }
</style></head><body>
<nav><a href="index.html">Fleet</a><a href="alarms.html">Alarm list</a>
<span class="note">{{ subtitle }}</span></nav>
{% block body %}{% endblock %}
</body></html>
"""

STATE = """{% macro state(s) -%}
<span class="state {{ s|replace('?', '')|replace('wearing', 'wearing') }}">{{ {'fault': 'FAULT',
'sensor_fault': 'SENSOR FAULT', 'wearing?': 'WEARING?', 'healthy': 'healthy',
'not_judged': 'not judged', 'error': 'error'}.get(s, s) }}</span>
{%- endmacro %}"""

INDEX = (
    STATE
    + """{% extends "base" %}{% block body %}
{% if machines %}<h1>Fleet: {{ machines|length }} whole machines, {{ views|length }} loops,
{{ n_logs }} log loops</h1>
<h2>Machines</h2>
<p class="note">Each machine's verdict on its newest log names the loop (FAULT: stick); a
cell per loop, its verdict on that log (click for the loop's history). Uncommissioned: no
model of this machine's loop (no commissioning data, or its training failed), so the loop is
not judged (or was judged with another machine's model, its alarms withheld); never
healthy. The pump (the config's pump:) is judged by its rule with the machine's own margin
law; with several alarms the machine's finding names one: the pump when its rule is in
fault, else the loop whose alarm came first.</p>
<table id="machines"><tr><th>machine</th><th>newest log</th><th>verdict</th>
{% for l in loops %}<th>{{ l }}</th>{% endfor %}</tr>
{% for m in machines %}<tr id="machine-{{ m.machine }}"><td>{{ m.machine }}</td>
<td>{{ m.log }}</td><td><span class="state {{ m.state }}">{{ m.text }}</span></td>
{% for l in loops %}<td data-loop="{{ l }}">{% if l in m.cells %}<a href="{{ pages[(m.machine,
l)] }}">{{ state(m.cells[l]) }}</a>{% else %}-{% endif %}</td>{% endfor %}</tr>
{% endfor %}</table>
{% for m in machines %}{% for l, why in m.why.items() %}<p class="note">{{ m.machine }}
{{ l }}: not judged: {{ why }}</p>{% endfor %}{% endfor %}
<h2>Each loop</h2>
{% else %}<h1>Fleet: {{ views|length }} machines, {{ n_logs }} logs</h1>{% endif %}
<p class="note">State: the newest log's verdict (WEARING?: healthy, but its typical residual
has doubled since commissioning). Fault / sensor: what the alarms name; a fault is named from
the isolation votes of all its alarm episodes. First warning: the first log before any alarm
at which the page would have warned. Click a machine for its history and the signals around
its alarms.</p>
<table id="fleet">
<tr><th>machine</th><th>state</th><th>fault / sensor</th><th>first seen</th>
<th>first warning</th><th>what to do</th><th>health index<br>(newest log, 1.0 = alarm)</th>
<th>logs</th><th>alarm episodes</th></tr>
{% for v in views %}<tr id="row-{{ v.machine }}{{ '-' ~ v.loop if v.loop else '' }}">
<td><a href="{{ v.page }}">{{ v.name }}</a>{% if v.rows[-1].model.startswith('default') %}
<br><span class="note">default model: no commissioning data</span>{% endif %}{% if
stats.get(v.name) %}<br><span class="note">{{ on_off(stats[v.name]) }}</span>{% endif
%}</td>
<td>{{ state(v.state) }}</td>
<td>{{ v.finding or '-' }}{% if v.evidence %}<br>
<span class="note">{{ v.evidence }}</span>{% endif %}</td>
<td>{{ v.since or '-' }}</td><td>{{ v.warning.text }}</td><td>{{ v.what_to_do }}</td>
<td class="num">{{ fmt(v.index) }}</td><td class="num">{{ v.rows|length }}</td>
<td class="num">{{ v.alarms|length }}</td></tr>
{% endfor %}</table>
<p><a href="alarms.html">Alarm list</a>: {{ unacked }} alarm episodes not acknowledged or
shelved.</p>
{% if older %}<p class="banner">{{ older }} logs with an alarm or sensor fault were judged
before the results kept alarm episodes: their episodes, codes and names are missing here.
Judge them again into a new results folder (<code>monitor fleet run FLEET --out NEW</code>).
</p>{% endif %}
{{ fleet_plot|safe }}
<h2>Fault codes (DM1 SPN/FMI) per period</h2>
<p class="note">Alarm episodes per J1939 trouble code and period (the day in the log's file
name), as the monitor on the machine sends them in DM1.</p>
{% if groups %}<table id="codes"><tr><th>SPN</th><th>FMI</th><th>meaning</th><th>machines</th>
{% for p in periods %}<th>{{ p }}</th>{% endfor %}</tr>
{% for g in groups %}<tr><td class="num">{{ g.spn }}</td><td class="num">{{ g.fmi }}</td>
<td>{{ g.what }}</td><td>{{ g.machines|join(', ') }}</td>
{% for p in periods %}<td class="num">{{ g.per_period.get(p, '') }}</td>{% endfor %}</tr>
{% endfor %}</table>{% else %}<p>No alarm episodes.</p>{% endif %}
{% if errors %}<h2>Logs that could not be judged</h2><ul>
{% for r in errors %}<li><code>{{ r.log }}</code>: {{ r.error }}</li>{% endfor %}</ul>{% endif %}
{% endblock %}"""
)

MACHINE = (
    STATE
    + """{% extends "base" %}{% block body %}
<h1>{{ v.name }} {{ state(v.state) }}</h1>
<p><b>Fault / sensor:</b> {{ v.finding or 'none' }}{% if v.since %} (first seen {{ v.since }},
last {{ v.last_seen }}){% endif %}{% if v.evidence %}; {{ v.evidence }}{% endif %}<br>
<b>What to do:</b> {{ v.what_to_do }}<br><b>First warning:</b> {{ v.warning.text }}<br>
<b>Drift from commissioning:</b> {{ '-' if v.drift is none else '%.1f x'|format(v.drift) }}
(median J of the last 3 logs over the commissioning run's; 2 x and above: wearing?)</p>
{% if stats %}<p><b>Commissioning, the statistics its model judges with</b> (each on only
when its held-out data earns its threshold):</p>
<ul id="statistics">{% for name, why in stats.items() %}<li><b>{{ name }}</b> {{ why }}</li>
{% endfor %}</ul>{% endif %}
{{ health_plot|safe }}
<h2>Alarm episodes</h2>
{% if v.alarms %}<table id="episodes"><tr><th>log</th><th>start [s into the log]</th>
<th>end [s]</th>
<th>duration [s]</th><th>fault / sensor</th><th>isolation votes</th><th>DM1 SPN</th><th>FMI</th>
<th>status</th></tr>
{% for a in v.alarms %}<tr><td>{{ a.log }}</td><td class="num">{{ '%.1f'|format(a.span.start_t)
}}</td>
<td class="num">{{ '%.1f'|format(a.span.end_t) }}{% if a.span.open
%} (open at the end of the log){% endif %}</td>
<td class="num">{{ '%.1f'|format(a.span.duration_s) }}</td><td>{{ a.what }}</td>
<td>{{ a.votes_text or ("- (the pump rule)" if a.loop == "pump" else "- (sensor check)")
}}</td><td class="num">{{ a.code.spn }}</td>
<td class="num">{{ a.code.fmi }}</td>
<td>{{ acks[a.id].text if a.id in acks else 'active' }}</td></tr>
{% endfor %}</table>{% else %}<p>No alarm episodes.</p>{% endif %}
<h2>Signals around alarms</h2>
{% for div in signal_plots %}{{ div|safe }}{% else %}<p class="note">{{ signals_note }}</p>{%
endfor %}
<h2>Every log</h2>
<p class="note">Health index: the log's largest alarm level (J / eps0 or a statistic beside
it over its threshold; 1.0 = alarm). Median J / eps0: the log's typical residual over the
alarm threshold. Drift: the log's median J over the commissioning run's (2 x and above:
wearing?). Judged: the seconds of the log the detector gave a verdict on.</p>
<table id="logs"><tr><th>#</th><th>log</th><th>verdict</th><th>health index</th>
<th>median J / eps0</th><th>drift</th><th>judged [s]</th><th>episodes</th><th>error</th></tr>
{% for r in v.rows %}<tr><td class="num">{{ loop.index }}</td><td>{{ r.log }}</td>
<td>{{ state(r.verdict) }}</td><td class="num">{{ fmt(index(r)) }}</td>
<td class="num">{{ fmt(r.p50_j_ratio) }}</td><td class="num">{{ fmt(r.p50_j_drift) }}</td>
<td class="num">{{ fmt(r.judged_s) }}</td><td class="num">{{ n_episodes(r) }}</td>
<td>{{ r.error or '' }}</td></tr>
{% endfor %}</table>
{% endblock %}"""
)

ALARMS = """{% extends "base" %}{% block body %}
<h1>Alarm list</h1>
{% if live %}<p class="banner">Acknowledge or shelve an alarm episode: your name, an optional
note, then the button. Shelving hides it for {{ shelve_days }} days. Kept in
<code>{{ ack_file }}</code> beside the results.</p>
{% else %}<p class="banner">This is the static page: it shows the acknowledgements kept in
<code>{{ ack_file }}</code> when it was written. To acknowledge or shelve alarms, run
<code>monitor fleet serve RESULTS</code> and open the address it prints.</p>{% endif %}
<table id="alarms"><tr><th>machine</th><th>log</th><th>start [s into the log]</th>
<th>duration [s]</th>
<th>fault / sensor</th><th>DM1 SPN / FMI</th><th>what to do</th><th>status</th>
{% if live %}<th>acknowledge / shelve</th>{% endif %}</tr>
{% for a in alarms %}<tr id="alarm-{{ loop.index }}" data-alarm="{{ a.id }}">
<td><a href="{{ a.page }}">{{ a.label }}</a></td><td>{{ a.log }}</td>
<td class="num">{{ '%.1f'|format(a.span.start_t) }}</td>
<td class="num">{{ '%.1f'|format(a.span.duration_s) }}</td>
<td>{{ a.what }}</td><td>{{ a.code.spn }} / {{ a.code.fmi }}</td><td>{{ a.action }}</td>
<td class="status">{{ acks[a.id].text if a.id in acks else 'active' }}</td>
{% if live %}<td><form class="ack" method="post" action="ack">
<input type="hidden" name="alarm" value="{{ a.id }}">
<input type="text" name="by" placeholder="your name" required>
<input type="text" name="note" placeholder="note">
<button name="action" value="acknowledge">Acknowledge</button>
<button name="action" value="shelve">Shelve</button>
</form></td>{% endif %}</tr>
{% else %}<tr><td colspan="8">No alarm episodes.</td></tr>{% endfor %}</table>
{% if shelved %}<h2>Shelved</h2><table id="shelved"><tr><th>machine</th><th>log</th>
<th>fault / sensor</th><th>status</th>{% if live %}<th></th>{% endif %}</tr>
{% for a in shelved %}<tr data-alarm="{{ a.id }}"><td>{{ a.label }}</td><td>{{ a.log }}</td>
<td>{{ a.what }}</td><td class="status">{{ acks[a.id].text }}</td>
{% if live %}<td><form class="ack" method="post" action="ack">
<input type="hidden" name="alarm" value="{{ a.id }}">
<input type="text" name="by" placeholder="your name" required>
<button name="action" value="unshelve">Unshelve</button></form></td>{% endif %}</tr>
{% endfor %}</table>{% endif %}
{% endblock %}"""
