function ds = load_fes_dataset(dir)
% LOAD_FES_DATASET  Read a data set: fes-dataset/1 (pulses and force) or fes-dataset/2
% (named continuous channels at any period), dataset.json plus one CSV per record. The
% `schema` field of dataset.json says which.
%
%   ds = load_fes_dataset('data/fast')     % fes-dataset/1
%   hs = load_fes_dataset('data/heat')     % fes-dataset/2
%
% fes-dataset/1 returns a struct:
%   ds.meta      dataset.json without its record list (schema, source, scale_n, offset_n,
%                ts_s, split, ...), as jsondecode gives it
%   ds.records   struct array, one element per record, in file order:
%                  file, kind, samples, pulses, split ('train', 'test' or ''),
%                  t_ms, pulse (logical), force (normalised), force_n (newtons),
%                  decided (logical; the pulses themselves when the file has no such column)
%   ds.train     indices into ds.records of the training records (1-based)
%   ds.test      indices of the test records (1-based)
%
% fes-dataset/2 returns a struct:
%   hs.meta      dataset.json without its record list (schema, source, seed, parameters,
%                protocol, ts_s, inputs, outputs, split)
%   hs.ts_s      the sample period, s
%   hs.channels  struct array, inputs first and then outputs (the record files' column
%                order after t_s): name, field (the channel's field name in `signals`: the
%                name made a valid identifier), role ('input' or 'output'), unit, range
%                ([lo hi], the physical values of the stored 0 and 1; [] if none)
%   hs.records   struct array, one element per record, in file order: file, kind, samples,
%                split, t0_s, t_s (column of sample times, t0_s + k * ts_s), signals (one
%                column per channel, by field name: r.signals.y), values (samples x
%                channels, in hs.channels order)
%   hs.train, hs.test   as for version 1
%   Physical values: c = hs.channels(k); c.range(1) + r.values(:, k) * diff(c.range).
%
% Checks the format as the Rust readers do; a violation is an error naming the file (and
% line). Needs jsondecode: MATLAB R2016b or later, GNU Octave 7 or later.
% Formats: docs/sim-muscle.md ("Data-set format"), crates/fes-dataset/src/signals.rs and
% docs/heat-transfer.md (version 2). Python: python/fes_io.py.

  meta_path = fullfile(dir, 'dataset.json');
  if ~exist(meta_path, 'file')
    error('fes:dataset', '%s: no dataset.json (not a data-set directory)', dir);
  end
  meta = jsondecode(fileread(meta_path));
  if ~isstruct(meta) || ~isscalar(meta)
    error('fes:dataset', '%s: not a JSON object', meta_path);
  end
  if isfield(meta, 'schema') && ischar(meta.schema) && strcmp(meta.schema, 'fes-dataset/2')
    ds = load_v2(dir, meta_path, meta);
    return;
  end
  if ~isfield(meta, 'schema') || ~ischar(meta.schema) || ~strcmp(meta.schema, 'fes-dataset/1')
    if isfield(meta, 'schema')
      found = jsonencode(meta.schema);
    else
      found = 'null';
    end
    error('fes:dataset', '%s: field `schema` is %s, expected one of "fes-dataset/1", "fes-dataset/2"', ...
          meta_path, found);
  end
  fields = {'scale_n', 'offset_n', 'ts_s', 'split', 'records'};
  for k = 1:numel(fields)
    if ~isfield(meta, fields{k})
      error('fes:dataset', '%s: missing field `%s`', meta_path, fields{k});
    end
  end
  entries = meta.records;
  if iscell(entries)
    entries = [entries{:}];
  end
  meta = rmfield(meta, 'records');
  n = numel(entries);
  if n < 2
    error('fes:dataset', '%s: %d record(s); a data set needs at least 2', meta_path, n);
  end
  train = meta.split.train(:)' + 1;
  test = meta.split.test(:)' + 1;
  if isempty(train) || isempty(test) || any([train test] < 1) || any([train test] > n) ...
      || ~isempty(intersect(train, test))
    error('fes:dataset', '%s: field `split` is not a valid train/test split of %d records', ...
          meta_path, n);
  end
  ts_ms = meta.ts_s * 1e3;
  records = struct('file', {}, 'kind', {}, 'samples', {}, 'pulses', {}, 'split', {}, ...
                   't_ms', {}, 'pulse', {}, 'force', {}, 'force_n', {}, 'decided', {});
  for i = 1:n
    e = entries(i);
    name = e.file;
    if isempty(name) || any(name == '/') || any(name == '\') || any(strcmp(name, {'.', '..', 'dataset.json'}))
      error('fes:dataset', '%s: field `records[%d].file`: `%s` is not a plain file name', ...
            meta_path, i - 1, name);
    end
    path = fullfile(dir, name);
    fid = fopen(path, 'r');
    if fid < 0
      error('fes:dataset', '%s: cannot open', path);
    end
    header = fgetl(fid);
    fclose(fid);
    header = strrep(strtrim(header), char([239 187 191]), '');
    switch header
      case 't_ms,pulse,force'
        width = 3;
      case 't_ms,pulse,force,decided'
        width = 4;
      otherwise
        error('fes:dataset', '%s:1: header `%s`; expected `t_ms,pulse,force` (or `t_ms,pulse,force,decided`)', ...
              path, header);
    end
    m = dlmread(path, ',', 1, 0);
    if size(m, 2) ~= width
      error('fes:dataset', '%s: %d column(s), expected %d (as the header)', path, size(m, 2), width);
    end
    t = m(:, 1);
    pulse = m(:, 2);
    force = m(:, 3);
    bad = find(~isfinite(m(:)), 1);
    if ~isempty(bad)
      [row, ~] = ind2sub(size(m), bad);
      error('fes:dataset', '%s:%d: a value is not a finite number', path, row + 1);
    end
    bad = find(pulse ~= 0 & pulse ~= 1, 1);
    if ~isempty(bad)
      error('fes:dataset', '%s:%d: field `pulse` is not 0 or 1', path, bad + 1);
    end
    steps = diff(t);
    bad = find(steps <= 0 | abs(steps - ts_ms) > 1e-3 * ts_ms, 1);
    if ~isempty(bad)
      error('fes:dataset', '%s:%d: field `t_ms`: step %g ms differs from ts_s = %g ms', ...
            path, bad + 2, steps(bad), ts_ms);
    end
    bad = find(force < -0.1 | force > 1.1, 1);
    if ~isempty(bad)
      error('fes:dataset', '%s:%d: field `force`: %g is outside [-0.1, 1.1]', path, bad + 1, force(bad));
    end
    if numel(t) ~= e.samples
      error('fes:dataset', '%s: samples is %d, but dataset.json lists %d', path, numel(t), e.samples);
    end
    if sum(pulse) ~= e.pulses
      error('fes:dataset', '%s: pulses is %d, but dataset.json lists %d', path, sum(pulse), e.pulses);
    end
    r.file = name;
    r.kind = e.kind;
    r.samples = numel(t);
    r.pulses = sum(pulse);
    if any(train == i)
      r.split = 'train';
    elseif any(test == i)
      r.split = 'test';
    else
      r.split = '';
    end
    r.t_ms = t;
    r.pulse = logical(pulse);
    r.force = force;
    r.force_n = force * meta.scale_n + meta.offset_n;
    if width == 4
      r.decided = logical(m(:, 4));
    else
      r.decided = r.pulse;
    end
    records(i) = r;
  end
  ds.meta = meta;
  ds.records = records;
  ds.train = train;
  ds.test = test;
end

function ds = load_v2(dir, meta_path, meta)
% fes-dataset/2 (crates/fes-dataset/src/signals.rs), with the checks of its Rust reader.
  check_object(meta_path, '', meta, {'schema', 'source', 'ts_s', 'inputs', 'outputs', 'split', 'records'}, ...
               {'seed', 'parameters', 'protocol'});
  if ~ischar(meta.source)
    bad(meta_path, 'source', 'not a string');
  end
  if isfield(meta, 'seed') && ~isempty(meta.seed) && ~is_index(meta.seed, true)
    bad(meta_path, 'seed', sprintf('%s is not an unsigned integer', jsonencode(meta.seed)));
  end
  if isfield(meta, 'parameters')
    p = meta.parameters;
    if ~isstruct(p) || ~isscalar(p)
      bad(meta_path, 'parameters', 'not a JSON object');
    end
    names = fieldnames(p);
    for k = 1:numel(names)
      v = p.(names{k});
      if ~isnumeric(v) || ~isscalar(v)
        bad(meta_path, ['parameters.' names{k}], sprintf('%s is not a number', jsonencode(v)));
      end
    end
  end
  ts = meta.ts_s;
  if ~isnumeric(ts) || ~isscalar(ts) || ~isfinite(ts) || ts <= 0
    bad(meta_path, 'ts_s', sprintf('%s is not a sample period > 0 s', jsonencode(ts)));
  end
  seen = {'t_s'};
  channels = struct('name', {}, 'field', {}, 'role', {}, 'unit', {}, 'range', {});
  roles = {'inputs', 'input'; 'outputs', 'output'};
  for w = 1:2
    which = roles{w, 1};
    list = as_cell(meta.(which));
    if isempty(list)
      bad(meta_path, which, 'at least one channel is needed');
    end
    for i = 1:numel(list)
      c = list{i};
      where = sprintf('%s[%d]', which, i - 1);
      check_object(meta_path, where, c, {'name', 'unit'}, {'range'});
      if ~ischar(c.unit)
        bad(meta_path, [where '.unit'], 'not a string');
      end
      name = c.name;
      if ~ischar(name) || isempty(name) || any(name == ',') || any(isspace(name))
        bad(meta_path, [where '.name'], ...
            sprintf('`%s` is not a column name (non-empty, no `,` or spaces)', to_text(name)));
      end
      if any(strcmp(seen, name))
        bad(meta_path, [where '.name'], sprintf('`%s` repeats (or is `t_s`)', name));
      end
      seen{end + 1} = name;
      range = [];
      if isfield(c, 'range') && ~isempty(c.range)
        range = c.range(:)';
        if ~isnumeric(range) || numel(range) ~= 2
          bad(meta_path, [where '.range'], sprintf('%s is not a pair of numbers', jsonencode(c.range)));
        end
        if ~all(isfinite(range)) || range(1) == range(2)
          bad(meta_path, [where '.range'], ...
              sprintf('[%g, %g] is not a finite, non-empty range', range(1), range(2)));
        end
      end
      channels(end + 1) = struct('name', name, 'field', '', 'role', roles{w, 2}, ...
                                 'unit', c.unit, 'range', range);
    end
  end
  fields = matlab.lang.makeUniqueStrings(matlab.lang.makeValidName({channels.name}));
  [channels.field] = fields{:};
  entries = as_cell(meta.records);
  n = numel(entries);
  for i = 1:n
    e = entries{i};
    where = sprintf('records[%d]', i - 1);
    check_object(meta_path, where, e, {'file', 'kind', 'samples'}, {});
    if ~ischar(e.kind)
      bad(meta_path, [where '.kind'], 'not a string');
    end
    if ~is_index(e.samples, true)
      bad(meta_path, [where '.samples'], sprintf('%s is not a count', jsonencode(e.samples)));
    end
  end
  split = meta.split;
  check_object(meta_path, 'split', split, {'train', 'test'}, {});
  if n < 2
    error('fes:dataset', '%s: field `records`: %d record(s); a data set needs at least 2 (train and test)', ...
          meta_path, n);
  end
  for which = {'train', 'test'}
    w = which{1};
    idx = split.(w);
    if ~(isnumeric(idx) && (isempty(idx) || (isvector(idx) && is_index(idx, false))))
      bad(meta_path, ['split.' w], 'not a list of record indices');
    end
    idx = idx(:)';
    if isempty(idx)
      bad(meta_path, ['split.' w], sprintf('the %s split is empty', w));
    end
    for k = 1:numel(idx)
      if idx(k) >= n
        bad(meta_path, ['split.' w], ...
            sprintf('record index %d is out of range (there are %d records)', idx(k), n));
      end
      if any(idx(1:k - 1) == idx(k))
        bad(meta_path, ['split.' w], sprintf('record index %d repeats', idx(k)));
      end
    end
  end
  train = split.train(:)';
  test = split.test(:)';
  both = train(ismember(train, test));
  if ~isempty(both)
    bad(meta_path, 'split', sprintf('record %d is in both train and test', both(1)));
  end
  files = {};
  for i = 1:n
    name = entries{i}.file;
    where = sprintf('records[%d].file', i - 1);
    if ~ischar(name) || isempty(name) || any(strcmp(name, {'.', '..', 'dataset.json'})) ...
        || any(name == '/') || any(name == '\') || any(name == char(0))
      bad(meta_path, where, sprintf('`%s` is not a plain file name inside the data-set directory', ...
                                    to_text(name)));
    end
    if any(strcmp(files, name))
      bad(meta_path, where, sprintf('`%s` is listed twice', name));
    end
    files{end + 1} = name;
  end
  expected = [{'t_s'}, {channels.name}];
  records = struct('file', {}, 'kind', {}, 'samples', {}, 'split', {}, 't0_s', {}, ...
                   't_s', {}, 'signals', {}, 'values', {});
  for i = 1:n
    e = entries{i};
    path = fullfile(dir, e.file);
    m = read_signal_record(path, ts, expected);
    samples = size(m, 1);
    if samples ~= e.samples
      error('fes:dataset', '%s: samples is %d, but dataset.json lists %d', path, samples, e.samples);
    end
    r.file = e.file;
    r.kind = e.kind;
    r.samples = samples;
    if any(train == i - 1)
      r.split = 'train';
    elseif any(test == i - 1)
      r.split = 'test';
    else
      r.split = '';
    end
    r.t0_s = m(1, 1);
    r.t_s = m(:, 1);
    r.values = m(:, 2:end);
    r.signals = struct();
    for k = 1:numel(channels)
      r.signals.(channels(k).field) = m(:, k + 1);
    end
    records(i) = r;
  end
  ds.meta = rmfield(meta, 'records');
  ds.ts_s = ts;
  ds.channels = channels;
  ds.records = records;
  ds.train = train + 1;
  ds.test = test + 1;
end

function m = read_signal_record(path, ts, expected)
% One fes-dataset/2 record file: a samples x (1 + channels) matrix, t_s first. Blank lines
% are skipped (line numbers count them).
  text = fileread(path);
  if numel(text) >= 3 && isequal(double(text(1:3)), [239 187 191])
    text = text(4:end);
  end
  lines = strsplit(text, char(10));
  lines = regexprep(lines, '\r$', '');
  lineno = find(~cellfun('isempty', regexp(lines, '\S', 'once')));
  lines = lines(lineno);
  if isempty(lines)
    found = '';
  else
    found = lines{1};
  end
  if ~isequal(strtrim(strsplit(found, ',')), expected)
    error('fes:dataset', '%s:1: field `header`: `%s` does not name the channels of dataset.json: expected `%s`', ...
          path, found, strjoin(expected, ','));
  end
  width = numel(expected);
  body = lines(2:end);
  lineno = lineno(2:end);
  if isempty(body)
    error('fes:dataset', '%s: %d sample(s); a record needs at least 2', path, numel(body));
  end
  parts = regexp(body, ',', 'split');
  counts = cellfun('numel', parts);
  bad_line = find(counts ~= width, 1);
  if ~isempty(bad_line)
    error('fes:dataset', '%s:%d: %d field(s), expected %d (as the header)', ...
          path, lineno(bad_line), counts(bad_line), width);
  end
  fields = strtrim(reshape([parts{:}], width, []));
  v = str2double(fields);
  literal_nan = ~cellfun('isempty', regexpi(fields, '^[+-]?nan$', 'once'));
  not_number = (isnan(v) & ~literal_nan) | imag(v) ~= 0;
  v = real(v);
  not_finite = ~not_number & ~isfinite(v);
  t = v(1, :);
  bad_step = [false, abs(diff(t) - ts) > 1e-3 * ts];
  first = find(any(not_number | not_finite, 1) | bad_step, 1);
  if ~isempty(first)
    line = lineno(first);
    k = find(not_number(:, first) | not_finite(:, first), 1);
    if ~isempty(k) && not_number(k, first)
      error('fes:dataset', '%s:%d: field `%s`: `%s` is not a number', path, line, expected{k}, fields{k, first});
    elseif ~isempty(k)
      error('fes:dataset', '%s:%d: field `%s`: %s is not finite', path, line, expected{k}, fields{k, first});
    end
    error('fes:dataset', '%s:%d: field `t_s`: step %g s differs from ts_s = %g s', ...
          path, line, t(first) - t(first - 1), ts);
  end
  if numel(t) < 2
    error('fes:dataset', '%s: %d sample(s); a record needs at least 2', path, numel(t));
  end
  m = v';
end

function check_object(meta_path, where, obj, required, optional)
% obj is a JSON object with every required field and no other than those and optional.
  if ~isstruct(obj) || ~isscalar(obj)
    bad(meta_path, where, 'not a JSON object');
  end
  if isempty(where)
    prefix = '';
  else
    prefix = [where '.'];
  end
  for k = 1:numel(required)
    if ~isfield(obj, required{k})
      error('fes:dataset', '%s: missing field `%s%s`', meta_path, prefix, required{k});
    end
  end
  names = fieldnames(obj);
  for k = 1:numel(names)
    if ~any(strcmp(names{k}, [required, optional]))
      error('fes:dataset', '%s: unknown field `%s%s`', meta_path, prefix, names{k});
    end
  end
end

function bad(meta_path, field, problem)
  error('fes:dataset', '%s: field `%s`: %s', meta_path, field, problem);
end

function ok = is_index(v, scalar)
  ok = isnumeric(v) && isreal(v) && all(isfinite(v(:))) && all(v(:) >= 0) && all(v(:) == round(v(:)));
  if scalar
    ok = ok && isscalar(v);
  end
end

function c = as_cell(v)
% A JSON list as jsondecode gives it (struct array, cell array or [] when empty) as a cell.
  if iscell(v)
    c = v(:)';
  elseif isstruct(v)
    c = num2cell(v(:)');
  elseif isempty(v)
    c = {};
  else
    c = {v};
  end
end

function s = to_text(v)
  if ischar(v)
    s = v;
  else
    s = jsonencode(v);
  end
end
