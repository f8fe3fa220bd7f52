function state = twostage_seed_state(seed, index)
  % TWOSTAGE_SEED_STATE  A generator state for experiment INDEX of a chart
  % whose seed is the decimal text SEED (a 64-bit number, more than a double
  % holds exactly): its digits in chunks of 9, then the index. Give it to
  % randn("state", ...) or rand("state", ...).
  digits = seed(:)';
  chunks = [];
  while !isempty(digits)
    take = min(9, numel(digits));
    chunks(end + 1) = str2double(digits(end - take + 1:end));
    digits = digits(1:end - take);
  end
  state = [chunks, index]';
end
