// The side panel: a slider per control from /api/scene, the display toggles, and the figures.

function element(tag, attributes = {}, ...children) {
  const e = document.createElement(tag);
  for (const [key, value] of Object.entries(attributes)) {
    if (key === 'class') e.className = value;
    else e.setAttribute(key, value);
  }
  e.append(...children);
  return e;
}

export function percentile(values, q) {
  if (values.length === 0) return NaN;
  const sorted = [...values].sort((a, b) => a - b);
  return sorted[Math.min(sorted.length - 1, Math.max(0, Math.ceil(q * sorted.length) - 1))];
}

const ms = value => (Number.isFinite(value) ? `${value.toFixed(1)} ms` : '–');

export class Panel {
  /**
   * @param root the panel's element
   * @param controls the scene's `controls`
   * @param handlers {onControl(name, value), onFull(on), onDifference(on), onExposure(exposure, gamma)}
   */
  constructor(root, controls, handlers) {
    this.root = root;
    this.values = {};
    this.sliders = {};
    const controlBox = element('section', {class: 'controls'}, element('h2', {}, 'Light'));
    for (const control of controls) {
      this.values[control.name] = control.value;
      const output = element('output', {}, `${control.value} ${control.unit}`);
      const slider = element('input', {
        type: 'range', min: control.min, max: control.max, step: control.step, value: control.value,
        'data-control': control.name, 'aria-label': control.label,
      });
      slider.addEventListener('input', () => {
        const value = Number(slider.value);
        this.values[control.name] = value;
        output.textContent = `${value} ${control.unit}`;
        handlers.onControl(control.name, value);
      });
      this.sliders[control.name] = {slider, output, control};
      controlBox.append(element('label', {}, element('span', {}, control.label), slider, output));
    }

    const exposure = element('input', {type: 'range', min: -6, max: 6, step: 0.1, value: 0, 'data-display': 'exposure'});
    const gamma = element('input', {type: 'range', min: 1, max: 3, step: 0.1, value: 2.2, 'data-display': 'gamma'});
    const exposureOut = element('output', {}, '0 EV');
    const gammaOut = element('output', {}, '2.2');
    const tone = () => {
      exposureOut.textContent = `${Number(exposure.value).toFixed(1)} EV`;
      gammaOut.textContent = Number(gamma.value).toFixed(1);
      handlers.onExposure(2 ** Number(exposure.value), Number(gamma.value));
    };
    exposure.addEventListener('input', tone);
    gamma.addEventListener('input', tone);
    this.full = element('input', {type: 'checkbox', 'data-toggle': 'full'});
    this.full.addEventListener('change', () => handlers.onFull(this.full.checked));
    this.difference = element('input', {type: 'checkbox', 'data-toggle': 'difference'});
    this.difference.addEventListener('change', () => handlers.onDifference(this.difference.checked));
    const display = element('section', {class: 'display'}, element('h2', {}, 'Display'),
      element('label', {}, element('span', {}, 'Exposure'), exposure, exposureOut),
      element('label', {}, element('span', {}, 'Gamma'), gamma, gammaOut),
      element('label', {class: 'toggle'}, this.full, element('span', {}, 'full calculation (no cache)')),
      element('label', {class: 'toggle'}, this.difference, element('span', {}, 'difference |cache − reference|')));

    this.fields = {};
    const field = (name, label) => {
      this.fields[name] = element('span', {'data-field': name}, '–');
      return element('div', {class: 'row'}, element('span', {class: 'label'}, label), this.fields[name]);
    };
    this.errorBar = element('div', {class: 'bar'}, element('div', {class: 'fill'}),
      element('div', {class: 'mark min'}), element('div', {class: 'mark max'}));
    const figures = element('section', {class: 'figures'}, element('h2', {}, 'Frame'),
      field('state', 'State'),
      field('keyError', 'Key error'), this.errorBar,
      field('progress', 'Points'),
      field('converged', 'Converged'),
      field('server', 'Server (ms)'),
      element('h2', {}, 'Page'),
      field('latency', 'Latency'),
      field('byState', 'By state (p50/p95)'),
      field('costs', 'Apply/upload/draw'),
      field('checksum', 'Checksum'),
      field('difference', 'Difference'));
    this.message = element('div', {class: 'message', role: 'alert'});
    root.append(controlBox, display, figures, this.message);
  }

  setControl(name, value) {
    const entry = this.sliders[name];
    if (!entry) return;
    entry.slider.value = value;
    this.values[name] = Number(entry.slider.value);
    entry.output.textContent = `${this.values[name]} ${entry.control.unit}`;
  }

  /** The latest update's figures. */
  showUpdate(update) {
    const f = this.fields;
    f.state.textContent = update.state;
    f.state.className = `state ${update.state}`;
    const err = update.key_error;
    if (!Number.isFinite(err) || !Number.isFinite(update.eps_max)) return this.showProgress(update);
    f.keyError.textContent = `${(100 * err).toPrecision(3)}%  (eps ${(100 * update.eps_min).toPrecision(3)}–${(100 * update.eps_max).toPrecision(3)}%)`;
    // The bar spans 0 .. 1.5 eps_max; marks at eps_min and eps_max.
    const full = 1.5 * update.eps_max || 1;
    this.errorBar.querySelector('.fill').style.width = `${Math.min(100, (100 * err) / full)}%`;
    this.errorBar.querySelector('.fill').className = `fill ${update.state}`;
    this.errorBar.querySelector('.min').style.left = `${(100 * update.eps_min) / full}%`;
    this.errorBar.querySelector('.max').style.left = `${(100 * update.eps_max) / full}%`;
    this.showProgress(update);
  }

  showProgress(update) {
    const f = this.fields;
    f.progress.textContent = `${update.points_done} / ${update.points_total}`;
    const t = update.timing_ms || {};
    f.server.textContent = Object.entries(t).map(([k, v]) => `${k} ${Number(v).toFixed(1)}`).join(', ');
  }

  showConverged(text) {
    this.fields.converged.textContent = text;
  }

  showStats(stats) {
    const f = this.fields;
    const first = stats.moves.map(m => m.firstImageMs);
    f.latency.textContent = `first image p50 ${ms(percentile(first, 0.5))}, p95 ${ms(percentile(first, 0.95))} (${first.length} moves)`;
    const byState = {};
    for (const m of stats.moves) (byState[m.state] ??= []).push(m.firstImageMs);
    f.byState.textContent = Object.entries(byState)
      .map(([state, v]) => `${state} ${percentile(v, 0.5).toFixed(0)}/${percentile(v, 0.95).toFixed(0)}`).join(', ') || '–';
    const c = stats.costs;
    f.costs.textContent = c.length ? `p95 ${percentile(c.map(x => x.apply), 0.95).toFixed(1)} / ${percentile(c.map(x => x.upload), 0.95).toFixed(1)} / ${percentile(c.map(x => x.draw), 0.95).toFixed(1)} ms` : '–';
    f.checksum.textContent = stats.checksumErrors ? `${stats.checksumErrors} MISMATCHES` : `${stats.checksumsVerified} verified`;
    f.checksum.className = stats.checksumErrors ? 'bad' : '';
  }

  showDifference(text) {
    this.fields.difference.textContent = text;
  }

  /** A visible error line (checksum mismatch, server error); stays until replaced. */
  showError(text) {
    this.message.textContent = text;
    this.message.classList.add('visible');
  }
}
