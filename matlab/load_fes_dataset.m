function ds = load_fes_dataset(dir)
% LOAD_FES_DATASET  Read a fes-dataset/1 data set (dataset.json plus one CSV per record).
%
%   ds = load_fes_dataset('data/fast')
%
% Returns a struct:
%   ds.meta      dataset.json without its record list (schema, source, scale_n, offset_n,
%                ts_s, split, ...), as jsondecode gives it
%   ds.records   struct array, one element per record, in file order:
%                  file, kind, samples, pulses, split ('train', 'test' or ''),
%                  t_ms, pulse (logical), force (normalised), force_n (newtons),
%                  decided (logical; the pulses themselves when the file has no such column)
%   ds.train     indices into ds.records of the training records (1-based)
%   ds.test      indices of the test records (1-based)
%
% Checks the schema, each record file's header, the counts dataset.json lists and the
% format's value rules; a violation is an error naming the file (and line).
% Needs jsondecode: MATLAB R2016b or later, GNU Octave 7 or later.
% Format: docs/sim-muscle.md ("Data-set format"). Python: python/fes_io.py.

  meta_path = fullfile(dir, 'dataset.json');
  if ~exist(meta_path, 'file')
    error('fes:dataset', '%s: no dataset.json (not a data-set directory)', dir);
  end
  meta = jsondecode(fileread(meta_path));
  if ~isfield(meta, 'schema') || ~strcmp(meta.schema, 'fes-dataset/1')
    error('fes:dataset', '%s: field `schema` is not "fes-dataset/1"', meta_path);
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
