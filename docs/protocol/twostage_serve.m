function twostage_serve(simulate)
  % TWOSTAGE_SERVE  Serve a simulator to twostage over the protocol of
  % docs/protocol.md (version 1 or 2), reading requests on standard input and
  % writing records on standard output. Octave (octave-cli); the same code
  % is MATLAB syntax, but MATLAB has no standard input to read from.
  %
  %   twostage_serve(@simulate)
  %
  % simulate(theta, seed, index, n) returns [inputs, outputs]: n x n_u and
  % n x n_y matrices (n_u may be 0). Draw every random number from seed and
  % index, e.g. randn("state", twostage_seed_state(seed, index)), so that
  % experiment i of a chart is always the same. An error thrown by
  % simulate fails that experiment only. Under version 2 (protocol = 2 in
  % the model file) it is called simulate(theta, seed, index, n, noiseless,
  % u): noiseless true leaves every noise out, u is the n x n_u input to
  % apply (return it as the inputs; the same for every experiment of a
  % request, or each its own) or [] for the simulator's own.
  greeting = strsplit(strtrim(next_line()), " ");
  if numel(greeting) != 6 || !strcmp(greeting{1}, "twostage") || !any(strcmp(greeting{2}, {"1", "2"}))
    fprintf(stderr, "not a twostage greeting of version 1 or 2: %s\n", strjoin(greeting, " "));
    exit(2);
  end
  version = str2double(greeting{2});
  shape = str2double(greeting(3:6));
  nu = shape(2); ny = shape(3); n = shape(4);
  fprintf(stdout, "ready\n");
  fflush(stdout);
  while true
    line = next_line();
    if !ischar(line) || strncmp(line, "quit", 4)
      break;
    end
    words = strsplit(strtrim(line), " ");
    count = str2double(words{2});
    noiseless = false;
    mode = "own";
    asked = n;
    if version >= 2
      noiseless = strcmp(words{3}, "noiseless");
      mode = words{4};
      % A fifth word: the records' length, when not the greeting's.
      if numel(words) >= 5
        asked = str2double(words{5});
      end
    end
    % `given`: one input after the experiments' lines; `each`: every
    % experiment's own input after its line.
    jobs = cell(count, 1);
    inputs = cell(count, 1);
    for k = 1:count
      jobs{k} = strsplit(strtrim(next_line()), " ");
      if strcmp(mode, "each")
        inputs{k} = read_input(asked, nu);
      end
    end
    if strcmp(mode, "given")
      given = read_input(asked, nu);
      inputs(:) = {given};
    end
    for k = 1:count
      job = jobs{k};
      index = job{1};
      seed = job{2};
      theta = str2double(job(3:end));
      try
        if version >= 2
          [u, y] = simulate(theta, seed, str2double(index), asked, noiseless, inputs{k});
        else
          [u, y] = simulate(theta, seed, str2double(index), n);
        end
        if rows(y) != asked || columns(y) != ny || (nu > 0 && (rows(u) != asked || columns(u) != nu))
          error("the record is %dx%d and %dx%d, the request asked for %d samples of %d input(s) and %d output(s)",
                rows(u), columns(u), rows(y), columns(y), asked, nu, ny);
        end
        fprintf(stdout, "record %s\n", index);
        values = [reshape(u, asked, nu), y]';
        fprintf(stdout, [repmat("%.17g ", 1, nu + ny - 1), "%.17g\n"], values);
      catch err
        fprintf(stdout, "error %s %s\n", index, strrep(err.message, "\n", " "));
      end
    end
    fflush(stdout);
  end
end

function u = read_input(samples, nu)
  % A given input: one line of nu values per sample.
  u = zeros(samples, nu);
  for t = 1:samples
    u(t, :) = str2double(strsplit(strtrim(next_line()), " "));
  end
end

function line = next_line()
  % One line of standard input, or -1 at its end. input() reads a line as
  % it arrives; fgetl(stdin) waits for a buffer to fill, which would
  % deadlock the exchange.
  try
    line = input("", "s");
  catch
    line = -1;
  end
end
